"""Stored runs with damaged files (issue 31 item 5; docs/formats/store.md, "Damaged files").

One real run (module fixture: the four-bar, in-house rk4+none at three steps, 0.2 s, plus a
one-search stability sweep; computed in this process, stored as ``mbh run`` stores it) is copied
for each test and one of its files cut in half, overwritten
with garbage, emptied or removed: a case part, a sweep part, the manifest, a trajectory.  Every
reader — :func:`load_run`, :meth:`RunStore.cases`, ``mbh runs``, ``mbh show``, ``mbh report``,
``--resume`` — must read what is intact and name the damaged file and what was left out; never
raise a traceback, never drop a row without saying so.
"""

from __future__ import annotations

import contextlib
import io
import json
import shutil
import warnings
from pathlib import Path

import pandas as pd
import pytest

from mbh._harness import cli
from mbh._harness.run.row import run_spec
from mbh._harness.run.spec import CaseSpec, load_campaign
from mbh._harness.run.sweep import bisections, stability_sweep
from mbh._harness.store.manifest import list_runs
from mbh._harness.store.problems import MissingTrajectory, StoreError, StoreWarning
from mbh._harness.store.runs import RunStore, load_run
from tests.store.store_cases import RUNNABLE_CAMPAIGN

CAMPAIGN = RUNNABLE_CAMPAIGN + """[sweep]
scenarios = ["fourbar"]
adapters = ["inhouse"]
methods = ["rk4+direct"]
dt_min = 5e-3
dt_max = 1e-2
max_bisections = 1
"""

DAMAGE = {
    "cut in half": lambda path: path.write_bytes(path.read_bytes()[:path.stat().st_size // 2]),
    "garbage": lambda path: path.write_bytes(b"\x00garbage\xff" * 40),
    "empty": lambda path: path.write_bytes(b""),
}


def store_cases(store: RunStore, campaign, specs) -> None:
    """Run ``specs`` in this process and store them as the campaign runner does."""
    for spec in specs:
        outcome = run_spec(spec, campaign.bounds, campaign.accuracy)
        store.add(outcome.row, outcome.trajectory)


@pytest.fixture(scope="module")
def stored(tmp_path_factory) -> tuple[Path, Path, str]:
    """(campaign file, results root, run id) of the run every test copies."""
    folder = tmp_path_factory.mktemp("faults")
    path = folder / "faults.toml"
    path.write_text(CAMPAIGN, encoding="utf-8")
    campaign = load_campaign(path)
    store = RunStore.create(campaign, folder / "results")
    store_cases(store, campaign, campaign.cases)
    sweep = campaign.sweep

    def make_spec(scenario, adapter, method, dt):
        return CaseSpec(scenario, adapter, method, dt, sweep.t_end[scenario], 1, 60.0)

    def run(specs):
        return {spec.case_id: run_spec(spec, campaign.bounds, campaign.accuracy).row
                for spec in specs}

    stability_sweep(list(bisections(sweep)), make_spec, run, store.add_sweep)
    store.finish("complete")
    assert len(store.cases()) == 3 and len(store.sweeps()) == 1
    return path, folder / "results", store.run_id


@pytest.fixture
def run(stored, tmp_path) -> tuple[Path, Path, str]:
    """A fresh copy of the stored run: (campaign file, root, run id)."""
    campaign, root, run_id = stored
    shutil.copytree(root / run_id, tmp_path / "results" / run_id)
    return campaign, tmp_path / "results", run_id


def mbh(*argv) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        status = cli.main([str(a) for a in argv])
    return status, out.getvalue(), err.getvalue()


def case_ids(root: Path, run_id: str) -> list[str]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StoreWarning)
        return list(load_run(run_id, root)["case_id"])


# --- case and sweep parts ---------------------------------------------------------------------

@pytest.mark.parametrize("damage", sorted(DAMAGE))
def test_a_damaged_case_part_leaves_out_its_row_and_is_named(run, damage):
    _, root, run_id = run
    intact = case_ids(root, run_id)
    part = root / run_id / "cases" / "part-000001.parquet"
    DAMAGE[damage](part)

    with pytest.warns(StoreWarning, match=r"part-000001\.parquet: damaged part file"):
        cases = load_run(run_id, root)
    assert list(cases["case_id"]) == [intact[0], intact[2]]
    store = RunStore.open(run_id, root)
    store.cases()
    assert [problem.file for problem in store.problems] == [str(part)]
    assert store.problems[0].problem.endswith("its rows are left out")

    status, out, err = mbh("show", run_id, "--root", root)
    assert status == 0 and "2 cases of run" in out, (out, err)
    assert err.startswith(f"mbh: warning: {part}: damaged part file"), err


def test_a_part_whose_columns_fit_no_other_is_left_out_and_named(run):
    _, root, run_id = run
    part = root / run_id / "cases" / "part-000002.parquet"
    table = pd.read_parquet(part)
    table["status"] = [[1, 2]]  # a list where every other part holds a string
    table.to_parquet(part)
    store = RunStore.open(run_id, root)
    assert len(store.cases()) == 2
    assert [p.file for p in store.problems] == [str(part)]
    assert "do not fit" in store.problems[0].problem


def test_a_damaged_sweep_part_is_named_and_the_cases_read(run):
    _, root, run_id = run
    part = root / run_id / "sweeps" / "part-000000.parquet"
    DAMAGE["cut in half"](part)
    store = RunStore.open(run_id, root)
    assert store.sweeps().empty and len(store.cases()) == 3
    assert [p.file for p in store.problems] == [str(part)]


# --- the manifest -----------------------------------------------------------------------------

MANIFEST_DAMAGE = {**DAMAGE, "not an object": lambda path: path.write_text("[1, 2]"),
                   "no run id": lambda path: path.write_text(json.dumps({"status": "complete"}))}


@pytest.mark.parametrize("damage", sorted(MANIFEST_DAMAGE))
def test_a_damaged_manifest_lists_as_unreadable_and_its_rows_still_read(run, stored, damage):
    campaign, root, run_id = run
    other = RunStore.create(load_campaign(campaign), root)  # an intact run beside it
    other.finish("complete")
    manifest = root / run_id / "manifest.json"
    MANIFEST_DAMAGE[damage](manifest)

    listed = {m["run_id"]: m["status"] for m in list_runs(root)}
    assert listed == {run_id: "unreadable", other.run_id: "complete"}
    status, out, err = mbh("runs", "--root", root)
    assert status == 0 and other.run_id in out and f"{run_id}  " in out
    assert err.startswith(f"mbh: warning: {manifest}: "), err

    with pytest.warns(StoreWarning, match="manifest.json"):
        assert len(load_run(run_id, root)) == 3
    status, out, err = mbh("show", run_id, "--root", root)
    assert status == 0 and "3 cases of run" in out and str(manifest) in err


def test_a_run_with_a_damaged_manifest_cannot_be_resumed(run):
    campaign, root, run_id = run
    manifest = root / run_id / "manifest.json"
    DAMAGE["cut in half"](manifest)
    before = manifest.read_bytes()
    with pytest.raises(StoreError, match=r"manifest\.json: unreadable manifest .* cannot be "
                                         r"written to"):
        RunStore.open(run_id, root).lock()
    status, out, err = mbh("run", campaign, "--resume", run_id, "--root", root, "--quiet")
    assert status == 2 and out == "" and err.startswith(f"mbh: {manifest}: unreadable manifest")
    assert manifest.read_bytes() == before
    assert sorted(p.name for p in (root / run_id / "cases").iterdir()) == \
        ["part-000000.parquet", "part-000001.parquet", "part-000002.parquet"]


# --- trajectories -----------------------------------------------------------------------------

def test_a_missing_trajectory_keeps_its_row_and_is_named(run):
    _, root, run_id = run
    store = RunStore.open(run_id, root)
    first = store.cases().iloc[0]
    (root / run_id / first["trajectory_file"]).unlink()
    store = RunStore.open(run_id, root)
    assert len(store.cases()) == 3
    assert [p.file for p in store.problems] == [str(root / run_id / first["trajectory_file"])]
    assert "missing trajectory" in store.problems[0].problem
    with pytest.raises(MissingTrajectory, match="no trajectory stored"):
        store.trajectory(first["case_id"])


@pytest.mark.parametrize("damage", sorted(DAMAGE))
def test_a_damaged_trajectory_is_a_missing_one_naming_the_file(run, damage):
    _, root, run_id = run
    store = RunStore.open(run_id, root)
    first = store.cases().iloc[0]
    path = root / run_id / first["trajectory_file"]
    DAMAGE[damage](path)
    with pytest.raises(KeyError, match=rf"{path.name}: damaged trajectory"):
        store.trajectory(first["case_id"])
    assert [p.file for p in store.problems] == [str(path)]


def test_the_report_of_a_damaged_run_is_built_and_says_what_is_left_out(run, tmp_path):
    _, root, run_id = run
    store = RunStore.open(run_id, root)
    cases = store.cases()
    DAMAGE["garbage"](root / run_id / "cases" / "part-000000.parquet")
    DAMAGE["cut in half"](root / run_id / cases.iloc[1]["trajectory_file"])
    status, out, err = mbh("report", run_id, "--root", root, "--out", tmp_path / "report",
                           "--format", "html")
    assert status == 0, err
    html = (tmp_path / "report" / "report.html").read_text(encoding="utf-8")
    assert "Damaged stored file, left out of this report" in html
    assert "part-000000.parquet: damaged part file" in html


# --- resume -----------------------------------------------------------------------------------

def test_resume_sets_a_damaged_part_aside_and_runs_its_case_again(run):
    """What ``--resume`` does with the store (mbh._harness.run.campaign: open, lock, skip the done
    cases, store the rest, finish)."""
    path, root, run_id = run
    intact = case_ids(root, run_id)
    part = root / run_id / "cases" / "part-000001.parquet"
    DAMAGE["garbage"](part)
    store = RunStore.open(run_id, root)
    store.lock()
    store.mark_running()
    campaign = load_campaign(path)
    done = store.done_case_ids()
    assert sorted(done) == sorted([intact[0], intact[2]])
    store_cases(store, campaign, [spec for spec in campaign.cases if spec.case_id not in done])
    store.finish("complete")
    assert case_ids(root, run_id) == [intact[0], intact[2], intact[1]]  # none lost, none twice
    assert part.with_name(part.name + ".damaged").is_file()
    aside = store.manifest["set_aside"]
    assert [entry["file"] for entry in aside] == [str(part)]
    assert RunStore.open(run_id, root).problems == []
