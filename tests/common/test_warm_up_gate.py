"""While ``mbh warm-up`` compiles, other processes wait for it at their first kernel
(harness/common/warm_up_gate.py); ``mbh warm-up -- COMMAND`` runs the command beside it."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from mbh._harness.common import warm_up_gate

#: Run in a child process: say it is about to wait for the warm-up, wait, say it passed.
WAITER = """
from mbh._harness.common.warm_up_gate import wait_for_warm_up
print("waiting", flush=True)
wait_for_warm_up()
print("passed", flush=True)
"""

#: Run as the command of `mbh warm-up -- COMMAND`: whether the gate is closed and this process
#: exempt from it, then a file that lets the (stand-in) warm-up end, then exit 3.
GATE_SEEN = """
import fcntl, os, pathlib, sys
from mbh._harness.common.warm_up_gate import WARMING_UP_ENV, gate_path
with open(gate_path(), "rb") as handle:
    try:
        fcntl.flock(handle, fcntl.LOCK_SH | fcntl.LOCK_NB)
        print("open")
    except BlockingIOError:
        print("closed")
print(os.environ.get(WARMING_UP_ENV, "not exempt"), flush=True)
pathlib.Path(sys.argv[1]).touch()
sys.exit(3)
"""


def _environment(cache) -> dict:
    return {key: value for key, value in os.environ.items()
            if key != warm_up_gate.WARMING_UP_ENV} | {"MBH_CACHE_HOME": str(cache)}


#: Run in a child process: close the gate (saying so) until a line arrives on stdin; its own
#: children are exempt.
HOLDER = """
import os, sys
from mbh._harness.common.warm_up_gate import WARMING_UP_ENV, closed
with closed():
    print("closed", os.environ[WARMING_UP_ENV], flush=True)
    sys.stdin.readline()
print(os.environ.get(WARMING_UP_ENV, "unset"), flush=True)
"""


def test_a_process_waits_while_the_gate_is_closed_and_not_after(tmp_path):
    env = _environment(tmp_path)
    holder = subprocess.Popen([sys.executable, "-c", HOLDER], env=env, text=True,
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE)
    assert holder.stdout.readline() == "closed 1\n"
    waiter = subprocess.Popen([sys.executable, "-c", WAITER], env=env, text=True,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert waiter.stdout.readline() == "waiting\n"
    with pytest.raises(subprocess.TimeoutExpired):  # an open gate lets it end in ~1 ms
        waiter.wait(timeout=2)
    assert holder.communicate("go\n", timeout=60)[0] == "unset\n"
    out, err = waiter.communicate(timeout=60)
    assert waiter.returncode == 0 and out == "passed\n", err
    after = subprocess.run([sys.executable, "-c", WAITER], env=env, text=True,
                           capture_output=True, timeout=60, check=True)
    assert after.stdout == "waiting\npassed\n"


def test_warm_up_runs_its_command_beside_the_closed_gate_and_returns_its_code(tmp_path,
                                                                              monkeypatch):
    """The command starts once the gate is closed, is not exempt from it, and its exit code is
    the warm-up's.  The warm-up itself is made to do nothing (no phases, no fill cases)."""
    script = f"""
import pathlib, sys, time
from mbh._harness import cli
from mbh._harness.run import warm_up

def stand_in(jobs):  # the warm-up's compilation, ended by the command
    while not pathlib.Path({str(tmp_path / "seen")!r}).exists():
        time.sleep(0.05)
    return []

warm_up.warm_up = stand_in
sys.exit(cli.main(["warm-up", "--quiet", "--", sys.executable, "-c", {GATE_SEEN!r},
                   {str(tmp_path / "seen")!r}]))
"""
    done = subprocess.run([sys.executable, "-c", script], env=_environment(tmp_path),
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 3, done.stderr
    assert done.stdout.split() == ["closed", "not", "exempt"], done.stderr
    assert "warmed up: 0 cases" in done.stderr  # the summary leaves stdout to the command
