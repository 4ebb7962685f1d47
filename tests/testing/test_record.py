"""Record, then assert (``pytest --mbh-record``): a user's first session writes the tolerance file
from the errors it measured (10 × each, rounded up), reporting every recording test failed as
recorded; later plain sessions assert against the file, and a tightened file fails.

The user's suite runs outside the checkout, in a temporary folder, through ``python -m pytest``
(the plugin is found through its entry point).  Its cases are cheap: MuJoCo on the four-bar over
0.3 s.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from mbh._harness.testing.recording import dumps, recorded_entry, rounded_up
from mbh.testing import CaseRunner, ToleranceError, Tolerances, case_spec

#: A user's test file whose cases are held to the tolerance file beside it.
USER_TESTS = '''
import pytest

from mbh.testing import assert_within_tolerance, case_spec

CASES = [case_spec("fourbar", "mujoco", "best", dt, t_end=0.3) for dt in (1e-3, 1e-2)]


@pytest.mark.parametrize("case", CASES, ids=["dt1e-3", "dt1e-2"])
def test_case(case, mbh_runner, mbh_tolerances):
    assert_within_tolerance(mbh_runner.run(case), mbh_tolerances.for_case(case))
'''


def pytest_in(folder: Path, *args: str) -> subprocess.CompletedProcess:
    """``python -m pytest -q`` in ``folder`` (its own rootdir), without the short test summary.

    The summary repeats a failure's message only when the terminal is wide enough for it, so
    counting messages with it on depends on the terminal the suite runs in (``-rN`` turns it off).
    """
    return subprocess.run([sys.executable, "-m", "pytest", "-q", "-rN", "-p", "no:cacheprovider",
                           *args],
                          cwd=folder, capture_output=True, text=True, timeout=600, check=False)


def test_a_first_session_records_later_ones_assert_and_a_tightened_file_fails(tmp_path):
    (tmp_path / "test_solver.py").write_text(USER_TESTS)
    recorded = pytest_in(tmp_path, "--mbh-record")
    assert recorded.returncode == 1, recorded.stdout + recorded.stderr
    assert "2 failed" in recorded.stdout
    file = tmp_path / "tolerances.toml"
    assert recorded.stdout.count(f"mbh: tolerances recorded into {file} (--mbh-record)") == 2
    assert f"mbh: recorded 2 cases' tolerances into {file} (margin 10 x" in recorded.stdout

    measured = CaseRunner().case("fourbar", "mujoco", "best", dt=1e-3, t_end=0.3)
    tolerance = Tolerances(file).for_case(measured.spec)
    error = abs(measured.output("crank_angle")[1] - measured.reference_output("crank_angle")).max()
    assert tolerance.outputs["crank_angle"].atol == rounded_up(10 * error)
    assert tolerance.status == "ok" and tolerance.energy_error > 0

    plain = pytest_in(tmp_path)
    assert plain.returncode == 0 and "2 passed" in plain.stdout, plain.stdout + plain.stderr

    text = file.read_text()
    tight = text.replace(f"crank_angle = {{ atol = {tolerance.outputs['crank_angle'].atol!r} }}",
                         "crank_angle = { atol = 1e-12 }")
    assert tight != text
    file.write_text(tight)
    failed = pytest_in(tmp_path)
    assert "1 failed, 1 passed" in failed.stdout, failed.stdout + failed.stderr
    assert "output crank_angle is not within tolerance of the reference" in failed.stdout


def test_recording_refuses_a_margin_of_one_or_less(tmp_path):
    (tmp_path / "test_solver.py").write_text(USER_TESTS)
    done = pytest_in(tmp_path, "--mbh-record", "--mbh-record-margin", "0.5")
    assert done.returncode == 4  # a usage error
    assert "--mbh-record-margin: expected a number > 1, got 0.5" in done.stderr


@pytest.mark.parametrize("value, expected", [(5.83e-7, 5.9e-7), (1.0e-3, 1.0e-3), (9.91, 10.0),
                                             (0.5, 0.5), (1.234e-12, 1.3e-12)])
def test_recorded_values_round_up_to_two_digits(value, expected):
    assert rounded_up(value) == expected


def test_a_recorded_entry_is_the_margin_times_the_measured_value_above_its_floor():
    measured = {"status": "ok", "outputs": {"angle": 1.23e-7, "rate": 0.0},
                "constraint_violation": 4e-14, "energy_error": 2.1e-6}
    assert recorded_entry(measured, 10.0) == {
        "status": "ok", "outputs": {"angle": {"atol": 1.3e-6}, "rate": {"atol": 1e-11}},
        "constraint_violation": 1e-11, "energy_error": 2.1e-5}
    assert recorded_entry({"status": "failed"}, 10.0) == {"status": "failed"}


def test_a_written_file_reads_back_with_its_keys_quoted_where_toml_needs_it(tmp_path):
    entry = {"status": "ok", "outputs": {"crank_angle": {"atol": 1.3e-6}},
             "constraint_violation": 2e-9, "order": [1.7, 2.3]}
    document = {"/home/me/scenes/arm.toml": {"mujoco": {"rk4+direct": {"dt": {"1e-3": entry}}}},
                "*": {"*": {"*": {"status": "ok"}}}}
    path = tmp_path / "tolerances.toml"
    path.write_text(dumps(document))
    assert '["/home/me/scenes/arm.toml".mujoco."rk4+direct".dt."1e-3"]' in path.read_text()
    read = Tolerances(path).for_case(case_spec("/home/me/scenes/arm.toml", "mujoco", "rk4+direct",
                                               1e-3, t_end=1.0))
    assert (read.outputs["crank_angle"].atol, read.constraint_violation, read.order) == (
        1.3e-6, 2e-9, (1.7, 2.3))


def test_a_step_the_file_holds_no_table_for_is_an_error_not_a_pass(tmp_path):
    path = tmp_path / "tolerances.toml"
    path.write_text('[fourbar.mujoco.best.dt."1e-3"]\nstatus = "ok"\n'
                    '[fourbar.mujoco.best.dt."1e-2"]\nstatus = "ok"\n')
    tolerances = Tolerances(path)
    assert tolerances.for_case(case_spec("fourbar", "mujoco", "best", 1e-2, 0.5)).status == "ok"
    with pytest.raises(ToleranceError, match=re.escape(
            "no tolerance for fourbar.mujoco.best at dt 5e-3 s: its entries hold the steps "
            "1e-3, 1e-2 s only")):
        tolerances.for_case(case_spec("fourbar", "mujoco", "best", 5e-3, 0.5))
