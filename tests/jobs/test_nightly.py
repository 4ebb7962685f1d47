"""``mbh nightly --gate previous``: twice in a row no regression; an injected regression is named
and fails it (the history gate: tests/jobs/test_nightly_history.py).

The campaign is three cheap four-bar cases (1 s, three timing repetitions each: the in-house ones
at dt 1e-4 s, ~11 ms a run, Pinocchio at 1e-3 s, ~40 ms) in a temporary results root.  At 1e-3 s
an in-house run took ~1.1 ms, and one preemption by the scheduler (~4 ms, the test session's and
the campaign's workers sharing two cores) made a repetition ×4–5 slower: a `make test` run saw
two of three repetitions so, and the gate flagged both in-house cases.  The regressions are
injected by replacing the nightly's work function (``mbh._harness.jobs.nightly.case_work``, pytest
``monkeypatch``) with one that reports one case's error 1000 times larger and another case's
wall time 10,000 times longer; the adapters have no such switch.  Measured calibrated time
ratios between two plain runs: 0.78–1.2 on an idle machine, up to 2.03 with a second test
session on the same two cores, and 4.28 (the Pinocchio case, over the factor of 4 used then) in
a fresh clone's cold ``make test`` (2026-11-27), the other test worker compiling kernels.  A
repeat's time is the machine's load, not the code's, so the runs here use a time factor of 50
(the command's default is 2) and the injected slowdown is 10,000: the test checks that the gate
names a slower case and passes a repeat, not how small a slowdown it tells from the load.
About 30 s.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from mbh._harness import cli

from mbh._harness.jobs import nightly
from mbh._harness.run.row import CaseWork
from mbh._harness.store.manifest import list_runs
from tests.helpers import ROOT

CAMPAIGN = """
description = "nightly test: three cheap four-bar cases"
repetitions = 3
timeout_s = 120.0
accuracy = 1e-3

[t_end]
"*" = 1.0

[[group]]
scenarios = ["fourbar"]
methods = { inhouse = ["rk4+direct", "rk4+baumgarte"] }
dts = [1e-4]

[[group]]
scenarios = ["fourbar"]
methods = { pinocchio = ["best"] }
dts = [1e-3]
"""
LESS_ACCURATE = "fourbar|inhouse|rk4+baumgarte|0.0001|1.0"
SLOWER = "fourbar|pinocchio|best|0.001|1.0"
#: The calibrated-time threshold of these runs (see the module docstring).
TIME_FACTOR = 50.0
#: Injected factors: far past the thresholds (10 on the error, TIME_FACTOR on the time).
ERROR_INJECTED = 1e3
TIME_INJECTED = 1e4


@dataclass(frozen=True)
class InjectedWork(CaseWork):
    """The campaign's work, with one case reported less accurate and another slower."""

    def __call__(self, spec):
        row, trajectory = super().__call__(spec)
        if spec.case_id == LESS_ACCURATE:
            name = f"error_{row['main_output']}"
            row = {**row, "main_output_error": row["main_output_error"] * ERROR_INJECTED,
                   name: row[name] * ERROR_INJECTED}
        if spec.case_id == SLOWER:
            row = {**row, **{key: row[key] * TIME_INJECTED for key in
                             ("wall_time_s", "wall_time_per_sim_s", "wall_time_per_step_s")}}
        return row, trajectory


def run_nightly(campaign: Path, root: Path, capsys, *extra: str) -> tuple[int, str]:
    code = cli.main(["nightly", "--campaign", str(campaign), "--root", str(root), "--quiet",
                     "--workers", "2", "--gate", "previous", "--time-factor", str(TIME_FACTOR),
                     *extra])
    return code, capsys.readouterr().out


def test_nightly_twice_is_clean_and_an_injected_regression_fails_it(tmp_path, monkeypatch,
                                                                    capsys):
    campaign = tmp_path / "tiny.toml"
    campaign.write_text(CAMPAIGN)
    root = tmp_path / "results"
    step_summary = tmp_path / "step_summary.md"
    monkeypatch.setenv("GITHUB_STEP_SUMMARY", str(step_summary))

    code, out = run_nightly(campaign, root, capsys, "--no-report")
    assert code == 0, out
    assert "nothing to compare, no regression possible" in out

    code, out = run_nightly(campaign, root, capsys)  # with the report
    first, second = (m["run_id"] for m in list_runs(root))
    assert code == 0, out
    assert f"Compared with `{first}`: 3 cases in both runs; newly failing 0, less accurate 0, " \
           f"slower 0" in out
    assert "**No regression.**" in out
    folder = root / second
    assert (folder / "report" / "report.html").is_file() and (folder / "report" / "report.pdf").is_file()
    assert f"History page: `{folder / 'report' / 'history.html'}`." in out
    assert (folder / "report" / "history.html").is_file()
    assert (folder / nightly.SUMMARY_FILE).read_text() in step_summary.read_text()

    monkeypatch.setattr(nightly, "case_work",
                        lambda campaign: InjectedWork(campaign.bounds, campaign.accuracy))
    summary = tmp_path / "summary.md"
    code, out = run_nightly(campaign, root, capsys, "--no-report", "--summary", str(summary))
    assert code == 1, out
    assert "less accurate 1, slower 1" in out and "**2 regression(s):**" in out
    lines = {line.split("`")[1].replace("\\|", "|"): line for line in out.splitlines()
             if line.startswith("| `")}
    assert set(lines) == {LESS_ACCURATE, SLOWER}
    assert "| less accurate | ok → ok |" in lines[LESS_ACCURATE] and "(×1e+03)" in lines[LESS_ACCURATE]
    assert "| slower | ok → ok |" in lines[SLOWER]
    assert summary.read_text() in out


def test_workflow_runs_the_nightly_on_a_schedule_and_keeps_its_outputs():
    import yaml

    path = ROOT / ".github" / "workflows" / "nightly.yml"
    workflow = yaml.safe_load(path.read_text())
    triggers = workflow[True]  # YAML 1.1 reads the key `on` as true
    assert triggers["schedule"][0]["cron"] and "workflow_dispatch" in triggers
    steps = workflow["jobs"]["nightly"]["steps"]
    runs = " ".join(step.get("run", "") for step in steps)
    uses = [step.get("uses", "") for step in steps]
    assert "make .venv/.installed" in runs and "mbh nightly" in runs and "--root results" in runs
    assert sum(u.startswith("actions/cache@") for u in uses) == 2  # environment, references
    upload = next(step for step in steps if step.get("uses", "").startswith("actions/upload-artifact"))
    assert "report/" in upload["with"]["path"] and nightly.SUMMARY_FILE in upload["with"]["path"]
