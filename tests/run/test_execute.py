"""The executor (mbh._harness.run.executor): one process per case, warm (forked from the template) or
cold (a fresh interpreter); a hang, a kill, a segfault or an exception in a case becomes that
case's row, the other cases still run, an interrupt kills the running workers, and workers die
with a campaign process killed by SIGKILL.  Driven by a toy work function (defined here, run in the
worker processes)."""

from __future__ import annotations

import ctypes
import inspect
import multiprocessing.forkserver
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass

from pathlib import Path

import pytest

from mbh._harness.run.executor import WORKER_ENV, execute


@dataclass(frozen=True)
class ToySpec:
    """What the executor needs of a spec: a name for the toy work and a timeout."""

    name: str
    timeout_s: float = 30.0
    pid_file: str = ""


def toy_work(spec: ToySpec):
    """Misbehave as the spec's name says, else return a row with the worker's thread settings."""
    if spec.pid_file:  # written whole, then renamed: a reader that sees the file sees the pid
        Path(spec.pid_file + ".part").write_text(str(os.getpid()))
        os.replace(spec.pid_file + ".part", spec.pid_file)
    if spec.name.startswith("sigkill"):
        os.kill(os.getpid(), signal.SIGKILL)
    if spec.name.startswith("sleep"):
        time.sleep(600)
    if spec.name.startswith("memory"):
        raise MemoryError("toy allocation failed")
    if spec.name.startswith("segfault"):
        ctypes.string_at(0)
    if spec.name.startswith("exit"):
        os._exit(3)
    print("engine chatter on stdout")
    return {"name": spec.name, "status": "ok", "cwd": os.getcwd(),
            "mark": os.environ.get("MBH_TEST_MARK"),
            **{k: os.environ.get(k) for k in WORKER_ENV}}, None


def toy_failure_row(spec: ToySpec, status: str, reason: str) -> dict:
    return {"name": spec.name, "status": status, "reason": reason}


def run_toys(specs, **options) -> dict[str, dict]:
    rows = {}
    execute(specs, toy_work, failure_row=toy_failure_row, progress=False,
            on_result=lambda spec, row, trajectory: rows.__setitem__(spec.name, row), **options)
    assert len(rows) == len(specs)
    return rows


MISBEHAVING = [ToySpec("ok-1"), ToySpec("sigkill"), ToySpec("sleep", timeout_s=3.0),
               ToySpec("memory"), ToySpec("segfault"), ToySpec("exit"), ToySpec("ok-2")]


def check_misbehaving_rows(rows: dict[str, dict]) -> None:
    assert {name: row["status"] for name, row in rows.items()} == {
        "ok-1": "ok", "sigkill": "crashed", "sleep": "timeout", "memory": "crashed",
        "segfault": "crashed", "exit": "crashed", "ok-2": "ok"}
    assert rows["sigkill"]["reason"].startswith("worker process killed by SIGKILL")
    assert rows["segfault"]["reason"].startswith("worker process killed by SIGSEGV")
    assert "Segmentation fault" in rows["segfault"]["reason"]  # faulthandler's report is kept
    assert rows["memory"]["reason"].startswith("worker raised MemoryError: toy allocation failed")
    assert rows["exit"]["reason"].startswith("worker process exited with code 3")
    assert "timeout of 3 s" in rows["sleep"]["reason"]
    for name in ("ok-1", "ok-2"):
        assert all(rows[name][key] == "1" for key in WORKER_ENV)


@pytest.mark.parametrize("warm", [True, False], ids=["warm", "cold"])
def test_local_pool_turns_every_failure_into_a_row(warm):
    check_misbehaving_rows(run_toys(MISBEHAVING, workers=2, warm=warm))


def test_no_finished_case_is_read_as_crashed_when_cases_start_and_end_together(monkeypatch):
    """The fork server sends each exit code once, and multiprocessing's start of a process polls
    every live child (``_cleanup``).  Here a case's own read of its exit code is made 0.1 s slow
    while that poll's is not, so a start that meets a finishing case reads the code first: the
    order that, without the executor's poll lock, left the case's thread with nothing and a
    ``crashed`` row with exit code 255 (seen in CI; at least 4 of the 12 cases in each of two
    runs here without the lock, 2026-11-27).  Every row is ok."""
    real = multiprocessing.forkserver.read_signed

    def slow_unless_polled_by_a_start(fd):
        if not any(frame.function == "_cleanup" for frame in inspect.stack(0)):
            time.sleep(0.1)
        return real(fd)

    monkeypatch.setattr(multiprocessing.forkserver, "read_signed", slow_unless_polled_by_a_start)
    rows = run_toys([ToySpec(f"ok-{index}") for index in range(12)], workers=2)
    bad = {name: row["reason"] for name, row in rows.items() if row["status"] != "ok"}
    assert not bad, bad


def test_a_warm_worker_runs_in_the_callers_folder_and_environment_of_now(tmp_path, monkeypatch):
    run_toys([ToySpec("ok-before")], workers=1)  # the template is running from here on
    monkeypatch.setenv("MBH_TEST_MARK", "set after the template started")
    monkeypatch.chdir(tmp_path)
    row = run_toys([ToySpec("ok-after")], workers=1)["ok-after"]
    assert row["mark"] == "set after the template started"
    assert row["cwd"] == str(tmp_path) and row["OMP_NUM_THREADS"] == "1"


CAMPAIGN_PROCESS = """
import sys
from mbh._harness.run.executor import execute
from tests.run.test_execute import ToySpec, toy_failure_row, toy_work
execute([ToySpec("sleep", timeout_s=600.0, pid_file=sys.argv[1])], toy_work, workers=1,
        failure_row=toy_failure_row, progress=False, on_result=print, warm=sys.argv[2] == "warm")
"""


@pytest.mark.parametrize("warm", ["warm", "cold"])
def test_workers_die_with_a_campaign_process_killed_by_sigkill(tmp_path, warm):
    pid_file = tmp_path / "case.pid"
    campaign = subprocess.Popen([sys.executable, "-c", CAMPAIGN_PROCESS, str(pid_file), warm],
                                cwd=Path(__file__).resolve().parents[2])
    try:
        for _ in range(600):  # the case is running (its pid written)
            if pid_file.exists() and pid_file.read_text():
                break
            time.sleep(0.1)
        worker = int(pid_file.read_text())
        campaign.kill()
        campaign.wait()
        for _ in range(100):  # the kernel kills it (parent-death signal), within 10 s
            try:
                os.kill(worker, 0)
            except ProcessLookupError:
                break
            time.sleep(0.1)
        else:
            os.kill(worker, signal.SIGKILL)
            pytest.fail(f"{warm} worker {worker} outlived its campaign process")
    finally:
        campaign.kill()


def test_one_worker_runs_every_case_after_failures():
    rows = run_toys([ToySpec("sigkill"), ToySpec("memory"), ToySpec("ok")], workers=1)
    assert [rows[name]["status"] for name in ("sigkill", "memory", "ok")] == \
        ["crashed", "crashed", "ok"]


def test_timeout_argument_overrides_the_specs_own():
    rows = run_toys([ToySpec("sleep", timeout_s=600.0)], workers=1, timeout_s=2.0)
    assert rows["sleep"]["status"] == "timeout"


def test_dask_local_cluster_turns_every_failure_into_a_row():
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  host="127.0.0.1", dashboard_address=":0") as cluster:
        check_misbehaving_rows(run_toys(MISBEHAVING, scheduler=cluster.scheduler_address))


def test_interrupt_kills_the_running_workers(tmp_path):
    sleepers = [ToySpec(f"sleep-{i}", pid_file=str(tmp_path / f"{i}.pid")) for i in range(2)]
    stored = []

    def interrupt_after_first(spec, row, trajectory):
        stored.append(spec.name)
        for _ in range(600):  # both sleepers are inside their case (pid written) before Ctrl-C
            if all(os.path.exists(sleeper.pid_file) for sleeper in sleepers):
                break
            time.sleep(0.1)
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        execute([*sleepers, ToySpec("ok")], toy_work, workers=3, failure_row=toy_failure_row,
                progress=False, on_result=interrupt_after_first)
    assert stored == ["ok"]
    for sleeper in sleepers:
        pid = int(open(sleeper.pid_file).read())
        with pytest.raises(ProcessLookupError):  # killed and reaped, not left running
            os.kill(pid, 0)
