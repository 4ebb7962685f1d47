"""What `mbh`'s exit status says (docs/commands.md, "Exit status"): 0 ok, 1 a case or check that
did not pass, 2 bad input or usage (argparse's too, returned by `main`), 128 + N stopped by
signal N; and `mbh --version`.  The cases run on MuJoCo (no kernel to compile)."""

from __future__ import annotations

import importlib.metadata
import json

import pytest

from mbh._harness import cli
from mbh._harness.measure.metrics import case_metrics
from mbh._harness.model.trajectory import Trajectory
from mbh._harness.run.case import CaseResult

#: A short MuJoCo case on the four-bar, measured against its reference.
FOURBAR = ("simulate", "fourbar", "--adapter", "mujoco", "--method", "best", "--dt", "0.01",
           "--t-end", "0.5", "--json")


@pytest.fixture(autouse=True)
def results_root(tmp_path, monkeypatch):
    """An empty results root of the test's own."""
    monkeypatch.setenv("MBH_RESULTS_DIR", str(tmp_path / "results"))


def run(capsys, *argv) -> tuple[int, str, str]:
    status = cli.main(list(argv))
    out, err = capsys.readouterr()
    return status, out, err


def test_version_is_the_installed_distributions(capsys):
    status, out, _ = run(capsys, "--version")
    assert status == 0
    assert out.strip() == f"mbh {importlib.metadata.version('mbh')}"


def test_an_ok_case_exits_0_when_accurate_and_1_when_not(capsys):
    # measured: MuJoCo's best at dt 1e-2 is 5.7e-5 rad off the reference's crank angle by 0.5 s
    status, out, _ = run(capsys, *FOURBAR, "--accuracy", "1e-3")
    result = json.loads(out)
    assert (status, result["status"], result["accurate"]) == (0, "ok", True)
    status, out, _ = run(capsys, *FOURBAR, "--accuracy", "1e-6")
    result = json.loads(out)
    assert (status, result["status"], result["accurate"]) == (1, "ok", False)


def test_without_accuracy_the_status_alone_decides(capsys):
    # 'accurate' printed against a campaign's default (1e-6 rad), the exit status left to 'ok'
    status, out, _ = run(capsys, *FOURBAR)
    result = json.loads(out)
    assert (status, result["status"], result["accurate"]) == (0, "ok", False)


def test_a_case_without_reference_is_judged_by_its_status_alone(capsys):
    status, out, _ = run(capsys, *FOURBAR, "--no-reference")
    result = json.loads(out)
    assert (status, result["status"], result["accurate"]) == (0, "ok", None)


def test_a_case_that_breaks_its_bounds_exits_1(capsys):
    status, out, _ = run(capsys, *FOURBAR, "--bounds", "gap=1e-12", "--accuracy", "1")
    result = json.loads(out)
    assert (status, result["status"], result["accurate"]) == (1, "diverged", False)


@pytest.mark.parametrize("status", ["failed", "unsupported", "crashed", "timeout"])
def test_every_status_but_ok_exits_1(capsys, monkeypatch, status):
    from mbh._harness.run import case

    def ended(adapter, mech, *args):
        trajectory = Trajectory.empty(len(mech.bodies), status=status, reason="stub")
        return CaseResult(trajectory, case_metrics(mech, trajectory, None))

    monkeypatch.setattr(case, "run_case", ended)
    code, out, _ = run(capsys, *FOURBAR, "--no-reference")
    assert code == 1 and json.loads(out)["status"] == status


@pytest.mark.parametrize("argv,message", [
    (["simulate", "fourbar", "--adapter", "mujoco"], "the following arguments are required: --dt"),
    (["simulate", "fourbar", "--dt", "0.01", "--accuracy", "0"], "argument --accuracy: expected "
                                                                  "a finite number above 0"),
    (["nightly", "--error-factor", "1"], "argument --error-factor: expected a finite number "
                                         "above 1, got '1'"),
    (["run", "smoke", "--workers", "0"], "argument --workers: expected a whole number"),
    (["no-such-command"], "invalid choice: 'no-such-command'"),
    (["simulate", "fourbar", "--adapter", "mujoco", "--dt", "1e-300"],
     "mbh: dt: step 1e-300 s would take 4e+300 steps to 4 s (at most 1e+08)"),
    (["simulate", "fourbar", "--adapter", "nobody", "--dt", "0.01"],
     "mbh: adapter: unknown adapter 'nobody'"),
    (["run", "no_such_campaign"], "no such campaign file"),
    (["show", "no-such-run"], "mbh: no run 'no-such-run'"),
])
def test_bad_input_or_usage_exits_2(capsys, argv, message):
    status, out, err = run(capsys, *argv)
    assert status == 2 and out == ""
    assert message in err and "Traceback" not in err


def test_a_refused_reference_exits_1_with_its_reason(capsys, monkeypatch):
    from mbh._harness.references import build

    def refuse(mech, show_progress=None):
        raise build.ReferenceBuildError(f"{mech.name}: reference routes disagree (stub)")

    monkeypatch.setattr(build, "load_or_build", refuse)
    status, out, err = run(capsys, "reference", "fourbar", "--quiet")
    assert (status, out) == (1, "")
    assert err == "mbh: fourbar: reference routes disagree (stub)\n"


def test_a_command_stopped_by_ctrl_c_exits_130(capsys, monkeypatch):
    from mbh._harness.model import scenario

    def stopped():
        raise KeyboardInterrupt

    monkeypatch.setattr(scenario, "scenario_names", stopped)
    status, _, err = run(capsys, "scenarios")
    assert status == 130 and err == "mbh: interrupted\n"
