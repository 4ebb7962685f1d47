"""Where `mbh report` and `mbh history` write: ``reports/`` in the results root (``--root``, else
``$MBH_RESULTS_DIR``, else the default root), never elsewhere unless ``--out`` says so; and the
report's commands make the run again (a campaign run from a file is named by its path).

One stored run of a one-case MuJoCo campaign (computed in this process, stored as ``mbh run``
stores it)."""

from __future__ import annotations

import shlex
import shutil
from pathlib import Path

import pytest

from mbh._harness.common.locations import checkout, user_data
from mbh._harness.report.build import reproduce_commands
from mbh._harness.run.row import run_spec
from mbh._harness.run.spec import CAMPAIGN_DIR, load_campaign
from mbh._harness.store.runs import RunStore
from tests.helpers import run_mbh

CAMPAIGN = """\
description = "output folders test: one MuJoCo case"
repetitions = 1
calibration = false

[t_end]
"*" = 0.2

[[group]]
scenarios = ["fourbar"]
adapters = ["mujoco"]
methods = ["best"]
dts = [1e-2]
"""


@pytest.fixture(scope="module")
def stored(tmp_path_factory) -> tuple[Path, Path, str]:
    """(campaign file, results root, run id) of the stored run."""
    folder = tmp_path_factory.mktemp("outputs")
    path = folder / "one_case.toml"
    path.write_text(CAMPAIGN, encoding="utf-8")
    campaign = load_campaign(path)
    store = RunStore.create(campaign, folder / "results")
    for spec in campaign.cases:
        outcome = run_spec(spec, campaign.bounds, campaign.accuracy)
        store.add(outcome.row, outcome.trajectory)
    store.finish("complete")
    return path, folder / "results", store.run_id


@pytest.fixture
def root(stored, tmp_path, monkeypatch) -> Path:
    """A copy of the stored run's root, named by $MBH_RESULTS_DIR."""
    _, original, _ = stored
    copy = tmp_path / "results"
    shutil.copytree(original, copy)
    monkeypatch.setenv("MBH_RESULTS_DIR", str(copy))
    return copy


def _elsewhere(run_id: str) -> list[Path]:
    """The folders reports went to before they followed the results root."""
    return [folder / "reports" / run_id for folder in (checkout(), user_data()) if folder]


def test_report_and_history_default_to_the_results_root_of_the_environment(stored, root):
    _, _, run_id = stored
    status, out, err = run_mbh("report", run_id, "--format", "html")
    assert status == 0, err
    assert out.split() == [str(root / "reports" / run_id / "report.html")]
    assert (root / "reports" / run_id / "report.html").is_file()
    assert not any(folder.exists() for folder in _elsewhere(run_id))

    status, out, err = run_mbh("history")
    assert status == 0, err
    assert out.splitlines()[-1] == str(root / "reports" / "history-one_case" / "history.html")
    page = (root / "reports" / "history-one_case" / "history.html").read_text(encoding="utf-8")
    assert f'<a href="../{run_id}/report.html">{run_id}</a>' in page  # the report just built


def test_root_and_out_override_the_environment(stored, root, tmp_path):
    _, _, run_id = stored
    other = tmp_path / "other"
    shutil.copytree(root, other)
    status, out, err = run_mbh("report", run_id, "--root", str(other), "--format", "html")
    assert status == 0, err
    assert out.split() == [str(other / "reports" / run_id / "report.html")]
    status, out, err = run_mbh("report", run_id, "--format", "html", "--out",
                               str(tmp_path / "mine"))
    assert status == 0, err
    assert out.split() == [str(tmp_path / "mine" / "report.html")]
    status, out, err = run_mbh("history", "--out", str(tmp_path / "page"))
    assert status == 0, err
    assert out.splitlines()[-1] == str(tmp_path / "page" / "history.html")
    assert not (root / "reports").exists()


def test_the_reports_commands_name_a_campaign_file_by_its_path(stored, root):
    path, _, run_id = stored
    status, _, err = run_mbh("report", run_id, "--format", "html")
    assert status == 0, err
    html = (root / "reports" / run_id / "report.html").read_text(encoding="utf-8")
    assert f"mbh run {path}   # made run {run_id}\nmbh report {run_id}</pre>" in html
    # the campaign the command names is the one the run was made from
    manifest = RunStore.open(run_id, root).manifest
    command = reproduce_commands(manifest).splitlines()[0]
    argument = shlex.split(command, comments=True)[2]
    assert load_campaign(argument).text == manifest["campaign_text"]


def test_a_shipped_campaign_is_named_and_a_given_root_is_kept():
    manifest = {"run_id": "20260101T000000Z-smoke", "campaign": "smoke",
                "campaign_path": str(CAMPAIGN_DIR / "smoke.toml")}
    assert reproduce_commands(manifest) == ("mbh run smoke   # made run 20260101T000000Z-smoke\n"
                                            "mbh report 20260101T000000Z-smoke")
    odd = {**manifest, "campaign": "mine", "campaign_path": "/tmp/my campaigns/mine.toml"}
    assert reproduce_commands(odd, "20251231T000000Z-mine", Path("/data/results")) == (
        "mbh run '/tmp/my campaigns/mine.toml' --root /data/results   # made run "
        "20260101T000000Z-smoke\n"
        "mbh report 20260101T000000Z-smoke --against 20251231T000000Z-mine --root /data/results")
