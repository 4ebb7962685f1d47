"""The harness as a user installs it: one fresh virtual environment per test session, outside the
checkout, with the wheel built from the checkout, the tests' toy third-party adapter package
(written from the adapter guide: tests/adapters/conftest.py) and pytest installed at the tested
versions (constraints.txt), used from a folder of the user's with its own cache and data folders (XDG_CACHE_HOME, XDG_DATA_HOME).
Building it takes minutes: every suite using it is ``slow``."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.adapters.conftest import write_toy_package
from tests.helpers import ROOT


def run(command: list, cwd: Path, env: dict, timeout: float = 1800) -> subprocess.CompletedProcess:
    """``command`` in ``cwd`` with ``env``; fails the test with its output unless it exits 0."""
    done = subprocess.run([str(c) for c in command], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=timeout, check=False)
    assert done.returncode == 0, f"{command}: exit {done.returncode}\n{done.stdout}\n{done.stderr}"
    return done


@pytest.fixture(scope="session")
def installed(tmp_path_factory):
    """(venv bin folder, user folder, environment) with the wheel and the toy adapter installed."""
    base = tmp_path_factory.mktemp("installed")
    env = {key: value for key, value in os.environ.items()
           if not key.startswith(("MBH_", "PYTHON", "VIRTUAL_ENV", "NUMBA_CACHE"))}
    run([sys.executable, "-m", "pip", "wheel", ROOT, "--no-deps", "-q", "-w", base / "dist"],
        base, env)
    wheel, = (base / "dist").glob("mbh-*.whl")
    toy = write_toy_package(base / "mbh_toy_adapter")
    run([sys.executable, "-m", "venv", base / "venv"], base, env)
    bin_folder = base / "venv" / "bin"
    run([bin_folder / "python", "-m", "pip", "install", "-q", "-c", ROOT / "constraints.txt",
         wheel, toy, "pytest"], base, env)
    user = base / "user"
    user.mkdir()
    env |= {"XDG_CACHE_HOME": str(base / "cache"), "XDG_DATA_HOME": str(base / "data"),
            "PATH": f"{bin_folder}{os.pathsep}{env.get('PATH', '')}"}
    return bin_folder, user, env
