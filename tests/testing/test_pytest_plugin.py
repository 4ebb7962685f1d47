"""The pytest plugin and the tolerance helpers, used the way a user uses them.

User test files are written into a temporary folder and run by ``python -m pytest`` in a
subprocess (the plugin is found through its ``pytest11`` entry point); the documented example
suite is extracted from docs/formats/tolerances.md and run the same way.  Helper behaviour that needs no subprocess is
checked in-process.  Cases are cheap: the four-bar over 0.5 s at dt 1e-3 or 1e-2 s.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import mbh

from mbh._harness.run.case import CaseResult
from mbh._harness.testing.cases import (CaseRunner, SessionCase, ToleranceError, case_label,
                                        case_spec)
from mbh._harness.testing.tolerances import (Tolerances, assert_at_least_as_fast,
                                             assert_convergence_order, constraint_violation_series)
from mbh._harness.model.trajectory import Trajectory
from tests.helpers import example_suite_files

def run_pytest(folder: Path, *args: str) -> subprocess.CompletedProcess:
    """``python -m pytest -q`` in ``folder`` (its own rootdir), output as text."""
    return subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *args],
                          cwd=folder, capture_output=True, text=True, timeout=600, check=False)


@pytest.fixture(scope="module")
def runner() -> CaseRunner:
    return CaseRunner()


def test_readme_example_runs_as_pasted(tmp_path):
    files = example_suite_files()
    assert sorted(files) == ["my_campaign.toml", "test_mechanisms.py", "tolerances.toml"]
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    done = run_pytest(tmp_path, "-vv")  # -q -vv: one line per test
    assert done.returncode == 0, done.stdout + done.stderr
    # 2 plain tests + the campaign's 5 cases (2 steps × 2 methods + MuJoCo default at 1e-2 s).
    assert "7 passed" in done.stdout
    for case_id in ("fourbar-mujoco-best-dt1e-3", "fourbar-inhouse-rk4+direct-dt1e-2",
                    "fourbar-mujoco-default-dt1e-2"):
        assert f"test_campaign_case[{case_id}] PASSED" in done.stdout


def test_selection_options_skip_other_cases_with_the_reason(tmp_path):
    for name, text in example_suite_files().items():
        (tmp_path / name).write_text(text)
    done = run_pytest(tmp_path, "-rs", "--mbh-adapters", "inhouse")
    assert done.returncode == 0, done.stdout + done.stderr
    # inhouse: test_rk4_is_fourth_order + 2 campaign cases; mujoco: 1 plain test + 3 cases.
    assert "3 passed, 4 skipped" in done.stdout
    assert "adapter mujoco not selected (--mbh-adapters inhouse)" in done.stdout


USER_TESTS = '''
from mbh.testing import assert_close_to_reference, assert_constraint_violation_below


def test_sensible_tolerance(mbh_runner):
    result = mbh_runner.case("fourbar", "mujoco", "best", dt=1e-3, t_end=0.5)
    assert_close_to_reference(result, "crank_angle", atol=2e-6)


def test_too_tight_on_the_output(mbh_runner):
    result = mbh_runner.case("fourbar", "mujoco", "best", dt=1e-3, t_end=0.5)
    assert_close_to_reference(result, "crank_angle", atol=1e-9)


def test_too_tight_on_the_constraints(mbh_runner):
    result = mbh_runner.case("fourbar", "mujoco", "best", dt=1e-3, t_end=0.5)
    assert_constraint_violation_below(result, 1e-9)
'''


def test_user_file_passes_and_fails_with_a_readable_message(tmp_path, runner):
    (tmp_path / "test_user.py").write_text(USER_TESTS)
    done = run_pytest(tmp_path)
    assert done.returncode == 1, done.stdout + done.stderr
    assert "2 failed, 1 passed" in done.stdout
    # The expected worst sample, computed here from the same case (5.75e-7 rad at t = 0.5 s and
    # 4.5e-7 m when measured).
    result = runner.case("fourbar", "mujoco", "best", dt=1e-3, t_end=0.5)
    times, values = result.output("crank_angle")
    difference = np.abs(values - result.reference_output("crank_angle"))
    worst = int(np.argmax(difference))
    assert ("case fourbar-mujoco-best-dt1e-3 (t_end 0.5 s, status ok): output crank_angle is "
            "not within tolerance of the reference") in done.stdout
    assert (f"worst at t = {times[worst]:g} s: value {values[worst]:.10g}, reference "
            f"{result.reference_output('crank_angle')[worst]:.10g}, difference "
            f"{difference[worst]:.3g} > tolerance 1e-09") in done.stdout
    violation = constraint_violation_series(result)
    at = int(np.argmax(violation))
    assert (f"worst at t = {times[at]:g} s: value {violation[at]:.3g} m, reference 0, "
            f"difference {violation[at]:.3g} m > tolerance 1e-09 m") in done.stdout
    assert "tolerances.py" not in done.stdout  # the helpers' frames are hidden


def test_a_case_asked_for_twice_runs_once(runner):
    first = runner.case("fourbar", "mujoco", "best", dt=1e-2, t_end=0.2)
    again = runner.run(case_spec("fourbar", "mujoco", "best", 1e-2, 0.2))
    assert again is first
    assert case_label(first.spec) == "fourbar-mujoco-best-dt1e-2"
    assert sum(spec.startswith("fourbar|mujoco|best|0.01|0.2") for spec in runner.finished) == 1


def test_convergence_order_outside_its_band_names_the_steps(runner):
    results = runner.steps("fourbar", "inhouse", "rk4+direct", [1e-2, 5e-3], t_end=0.5)
    assert_convergence_order(results, 3.5, 4.5)  # measured 4.01 over 1e-2, 5e-3, 2e-3 s
    with pytest.raises(AssertionError, match=r"convergence order of crank_angle is 4\.\d+, "
                       r"outside \[1\.5, 2\.5\]\n  max error by step: dt 5e-3 → 7\.1\de-07, "
                       r"dt 1e-2 → 1\.1\de-05"):
        assert_convergence_order(results, 1.5, 2.5)


def synthetic(method: str, wall_time_s: float, calibration_s: float) -> SessionCase:
    """A finished case with a given wall time and session calibration time (no run)."""
    spec = case_spec("fourbar", "inhouse", method, 1e-3, 0.5)
    return SessionCase(spec, CaseResult(Trajectory.empty(3), {}, {"wall_time_s": wall_time_s}),
                       None, None, lambda: calibration_s)


def test_speed_is_compared_by_calibrated_time_ratio():
    fast = synthetic("rk4+direct", 0.2, 1.0)
    slow_elsewhere = synthetic("bdf4+direct", 0.6, 2.0)  # calibrated 0.3
    assert_at_least_as_fast(fast, slow_elsewhere)
    assert_at_least_as_fast(slow_elsewhere, fast, factor=1.5)  # ratio 1.5
    with pytest.raises(AssertionError, match=r"calibrated time 0\.3 against 0\.2 .*ratio 1\.5 > "
                                             r"tolerance 1\.4"):
        assert_at_least_as_fast(slow_elsewhere, fast, factor=1.4)


TOLERANCES = '''
["*"."*"."*"]
constraint_violation = 1e-3

[fourbar.inhouse."*"]
outputs = { crank_angle = { atol = 1e-6 } }

[fourbar.inhouse."rk4+direct"]
energy_error = 1e-5
order = [3.5, 4.5]

[fourbar.inhouse."rk4+direct".dt."1e-2"]
outputs = { crank_angle = { atol = 1e-4, rtol = 1e-3 } }
'''


def test_tolerance_entries_merge_from_wildcards_to_the_step(tmp_path):
    path = tmp_path / "tolerances.toml"
    path.write_text(TOLERANCES)
    tolerances = Tolerances(path)
    coarse = tolerances.for_case(case_spec("fourbar", "inhouse", "rk4+direct", 1e-2, 0.5))
    assert coarse.outputs["crank_angle"].atol == 1e-4 and coarse.outputs["crank_angle"].rtol == 1e-3
    assert (coarse.constraint_violation, coarse.energy_error, coarse.order) == (1e-3, 1e-5,
                                                                                (3.5, 4.5))
    fine = tolerances.for_case(case_spec("fourbar", "inhouse", "rk4+direct", 1e-3, 0.5))
    assert fine.outputs["crank_angle"].atol == 1e-6 and fine.status == "ok"
    other = tolerances.for_case(case_spec("slider_crank", "mujoco", "best", 1e-3, 0.5))
    assert other.outputs == {} and other.constraint_violation == 1e-3


@pytest.mark.parametrize("text,message", [
    ('[fourbar.mujoco.best]\natol = 1e-3\n', r"fourbar\.mujoco\.best\.atol: unknown key"),
    ('[fourbar.mujoco.best]\nstatus = "good"\n', r"fourbar\.mujoco\.best\.status: expected one of"),
    ('[fourbar.mujoco.best]\noutputs = { crank_angle = { atol = -1 } }\n',
     r"outputs\.crank_angle\.atol: expected a finite number >= 0, got -1"),
    ('[fourbar.mujoco.best.dt.fine]\nenergy_error = 1e-3\n',
     r"fourbar\.mujoco\.best\.dt\.fine: expected a step size in s"),
    ('[fourbar.mujoco.best]\norder = [3, 2]\n', r"order: expected \[low, high\] with low <= high"),
    ('[fourbar.mujoco]\nbest = 3\n', r"fourbar\.mujoco\.best: expected a table"),
])
def test_tolerance_file_mistakes_name_the_file_and_field(tmp_path, text, message):
    path = tmp_path / "tolerances.toml"
    path.write_text(text)
    with pytest.raises(ToleranceError, match=re.escape(str(path)) + ": .*" + message):
        Tolerances(path)


def test_a_case_without_an_entry_is_an_error(tmp_path):
    path = tmp_path / "tolerances.toml"
    path.write_text('[fourbar.mujoco.best]\nenergy_error = 1e-3\n')
    with pytest.raises(ToleranceError, match=r"no tolerance entry matches fourbar\.exudyn\.best "
                                             r"\(entries: fourbar\.mujoco\.best\)"):
        Tolerances(path).for_case(case_spec("fourbar", "exudyn", "best", 1e-3, 0.5))


def test_selection_names_unknown_scenarios_and_adapters():
    from mbh._harness.testing.cases import Selection

    with pytest.raises(ToleranceError, match=r"--mbh-adapters: unknown mujocco \(known: .*mujoco"):
        Selection.parse("fourbar", "mujocco")
    chosen = Selection.parse("fourbar, slider_crank", None)
    assert chosen.reason(case_spec("slider_crank", "exudyn", "best", 1e-3, 0.5)) is None
    assert chosen.reason(case_spec("fourbar_spatial", "exudyn", "best", 1e-3, 0.5)) == (
        "scenario fourbar_spatial not selected (--mbh-scenarios fourbar,slider_crank)")


def test_a_mechanism_without_outputs_must_be_given_the_output_to_compare():
    """A drawn pendulum that declares no output: its runs have no main output, and an assertion
    on the output says so instead of failing on an index."""
    mech = (mbh.MechanismBuilder("bare_pendulum", kind="planar", plane="xy", duration=1.0,
                                 gravity=[0.0, -9.81, 0.0])
            .body("arm", mass=1.0, inertia=[0.01, 0.1, 0.1], position=[0.5, 0.0, 0.0])
            .joint("O", "revolute", body1="ground", body2="arm", location=[0, 0, 0])
            .initial(driver="O", value=0.0, rate=0.0).build())
    spec = case_spec("bare_pendulum", "inhouse", "rk4+direct", 1e-3, 0.5)
    case = SessionCase(spec, CaseResult(Trajectory.empty(3), {}, {}), mech, None, lambda: 1.0)
    with pytest.raises(ToleranceError, match=r"scenario bare_pendulum declares no outputs, so "
                                             r"there is no main output to compare: declare one"):
        case.output()
