"""Isolated plugin cases (``--mbh-isolated``, marker ``mbh_isolated``): an adapter that segfaults
fails the test that ran it, with the signal named, and the session goes on to the next test; the
same suite without isolation ends at the crash (the user's whole session lost)."""

from __future__ import annotations

import subprocess
import sys

from tests.adapters.conftest import write_distribution

CRASHING_MODULE = '''
import ctypes

from mbh_toy_adapter import ToyAdapter


class CrashingAdapter(ToyAdapter):
    """The toy adapter, but building a model dereferences a null pointer."""

    def build(self, mechanism):
        ctypes.string_at(0)
'''

USER_SUITE = '''
import pytest

from mbh._harness.testing.tolerances import assert_status


MARKER
def test_the_crashing_engine(mbh_runner):
    assert_status(mbh_runner.case("fourbar", "crashing", "best", dt=1e-3, t_end=0.1))


def test_a_sound_engine_after_it(mbh_runner):
    assert_status(mbh_runner.case("fourbar", "mujoco", "best", dt=1e-3, t_end=0.1))
'''


def run_suite(tmp_path, toy_environment, marker: str) -> subprocess.CompletedProcess:
    site = tmp_path / "site"
    write_distribution(site, "mbh-crashing-adapter", "0.1.0",
                       {"crashing": "mbh_crashing_adapter:CrashingAdapter"})
    (site / "mbh_crashing_adapter.py").write_text(CRASHING_MODULE)
    suite = tmp_path / "suite"
    suite.mkdir()
    (suite / "test_engines.py").write_text(USER_SUITE.replace("MARKER", marker))
    environment = toy_environment | {"PYTHONPATH": f"{site}:{toy_environment['PYTHONPATH']}"}
    return subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider"],
                          cwd=suite, env=environment, capture_output=True, text=True,
                          timeout=600, check=False)


def test_a_segfaulting_adapter_fails_one_isolated_test_and_the_session_finishes(
        tmp_path, toy_environment):
    done = run_suite(tmp_path, toy_environment, "@pytest.mark.mbh_isolated")
    assert "1 failed, 1 passed" in done.stdout, done.stdout + done.stderr
    assert "crashed" in done.stdout and "SIGSEGV" in done.stdout


def test_without_isolation_the_crash_ends_the_session(tmp_path, toy_environment):
    done = run_suite(tmp_path, toy_environment, "")
    assert done.returncode == -11  # SIGSEGV: the session died, the second test never ran
    assert "passed" not in done.stdout
