"""``mbh nightly`` with the history gate (the default) on real stored runs: a tiny campaign run
five times, with changes injected from the third run on; then ``mbh history`` over those runs.

The changes are injected by replacing the nightly's work function (pytest ``monkeypatch``, as in
tests/jobs/test_nightly.py).  Every wall time, the calibration case's included, is set by the
injected work (0.01 s, one case ×20 when slowed; the calibration case's figure replaced too, as it
runs in the campaign's process or in a worker), so the calibrated times are exactly 1 or 20 and
the test does not depend on the machine's timing noise (the noise is the synthetic tests' job:
tests/report/test_history.py).  Expected, by the rules of harness/report/changepoints.py:

* run 3 (error ×1000 on one case, time ×20 on another): the error step is found at once (errors
  need one run), the time step not yet (a time step needs two runs): exit 1, one new regression;
* run 4: the time step is found, first at run 3; the error step was reported by run 3: exit 1,
  one new regression, one still open;
* run 5: both reported before: exit 0, two still open, both changed since the last good run
  (run 2); the history page is built and linked.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import pytest

from mbh._harness import cli
from mbh._harness.common.machine_speed import workload_name
from mbh._harness.jobs import nightly
from mbh._harness.run import campaign as campaign_run
from mbh._harness.run.calibration import CALIBRATION, WithCalibration
from mbh._harness.run.row import CaseWork
from mbh._harness.store.manifest import list_runs
from tests.helpers import run_mbh

pytestmark = pytest.mark.slow  # five campaign runs and one report: about a minute

CAMPAIGN = """
description = "nightly history test: three cheap four-bar cases"
repetitions = 1
timeout_s = 120.0
accuracy = 1e-3
calibration = true

[t_end]
"*" = 0.2

[[group]]
scenarios = ["fourbar"]
methods = { inhouse = ["rk4+direct", "rk4+baumgarte"], pinocchio = ["best"] }
dts = [1e-3]
"""
LESS_ACCURATE = "fourbar|inhouse|rk4+baumgarte|0.001|0.2"
SLOWER = "fourbar|pinocchio|best|0.001|0.2"
#: The wall time every case (and the calibration case) reports, s.
WALL_TIME = 0.01


@dataclass(frozen=True)
class ControlledWork(CaseWork):
    """The campaign's work with fixed wall times, one error multiplied by ``error_factor`` and one
    wall time by ``time_factor``."""

    error_factor: float = 1.0
    time_factor: float = 1.0

    def __call__(self, spec):
        row, trajectory = super().__call__(spec)
        row = {**row, "wall_time_s": WALL_TIME * (self.time_factor if spec.case_id == SLOWER
                                                  else 1.0)}
        if spec.case_id == LESS_ACCURATE:
            name = f"error_{row['main_output']}"
            row.update(main_output_error=row["main_output_error"] * self.error_factor,
                       **{name: row[name] * self.error_factor})
        return row, trajectory


def _fixed_calibration(spec) -> tuple[dict, None]:
    """The calibration case's row with the figure WALL_TIME.  Timed for real, the machine-speed
    workload varies from run to run (0.15–0.22 s on a busy 2-core machine), and a fresh-clone run
    of the slow suite saw a third case "changed since the last good run" from that alone."""
    return ({"case_id": spec.case_id, "status": "ok", "reason": "", "wall_time_s": WALL_TIME,
             "workload": workload_name()}, None)


@dataclass(frozen=True)
class FixedCalibration(WithCalibration):
    """:class:`WithCalibration` with :func:`_fixed_calibration` for the calibration case (the
    workers run it when the warm template is up already)."""

    def __call__(self, spec):
        return _fixed_calibration(spec) if spec == CALIBRATION else self.work(spec)


def _night(campaign, root, monkeypatch, capsys, injected: bool, *extra) -> tuple[int, str]:
    factors = {"error_factor": 1e3, "time_factor": 20.0} if injected else {}
    monkeypatch.setattr(campaign_run, "calibration_work", _fixed_calibration)
    monkeypatch.setattr(campaign_run, "WithCalibration", FixedCalibration)
    monkeypatch.setattr(nightly, "case_work", lambda c: ControlledWork(c.bounds, c.accuracy,
                                                                       **factors))
    code = cli.main(["nightly", "--campaign", str(campaign), "--root", str(root), "--quiet",
                     "--workers", "2", *extra])
    return code, capsys.readouterr().out


def _case_lines(out: str, heading: str) -> set[str]:
    """Case ids of the Markdown table that follows ``heading`` in the summary."""
    block = out.split(heading, 1)[1].split("\n\n", 2)[1]
    return {line.split("`")[1].replace("\\|", "|") + " " + line.split(" | ")[2]
            for line in block.splitlines() if line.startswith("| `")}


def test_history_gate_fails_each_new_regression_once(tmp_path, monkeypatch, capsys):
    campaign = tmp_path / "tiny.toml"
    campaign.write_text(CAMPAIGN)
    root = tmp_path / "results"
    for _ in range(2):
        code, out = _night(campaign, root, monkeypatch, capsys, False, "--no-report")
        assert code == 0 and "**No new regression.**" in out, out
        assert f"calibration case {WALL_TIME:.3g} s." in out  # not the machine's timing

    code, out = _night(campaign, root, monkeypatch, capsys, True, "--no-report")
    assert code == 1, out
    assert _case_lines(out, "**1 new regression(s):**") == {
        f"{LESS_ACCURATE} main-output error"}

    code, out = _night(campaign, root, monkeypatch, capsys, True, "--no-report")
    runs = [m["run_id"] for m in list_runs(root)]
    assert code == 1, out
    assert _case_lines(out, "**1 new regression(s):**") == {f"{SLOWER} calibrated wall time"}
    assert f"`{runs[2]}`" in out.split("**1 new regression(s):**")[1].split("\n\n")[1]
    record = json.loads((root / runs[3] / nightly.GATE_FILE).read_text())
    assert record == {"gate": "history", "passed": False,
                      "open": sorted([f"{LESS_ACCURATE}|main_output_error",
                                      f"{SLOWER}|calibrated_time"])}

    code, out = _night(campaign, root, monkeypatch, capsys, True)
    runs = [m["run_id"] for m in list_runs(root)]
    assert code == 0, out
    assert "**No new regression.**" in out
    assert _case_lines(out, "Still open, reported by an earlier nightly:") == {
        f"{LESS_ACCURATE} main-output error", f"{SLOWER} calibrated wall time"}
    assert f"Changed since the last good run `{runs[1]}`: 2." in out
    page = root / runs[4] / "report" / "history.html"
    assert f"History page: `{page}`." in out and page.is_file()
    html = page.read_text(encoding="utf-8")
    assert 'href="report.html"' in html  # this run's report, beside the page

    status, stdout, stderr = run_mbh("history", "--root", str(root), "--out",
                                     str(tmp_path / "page"), "--json")
    assert status == 0, stderr
    found = {(c["case_id"], c["quantity"], c["run_id"]) for c in json.loads(stdout)["changes"]}
    assert found == {(LESS_ACCURATE, "main_output_error", runs[2]),
                     (SLOWER, "calibrated_time", runs[2])}
