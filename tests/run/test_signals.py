"""Every way to stop a run (issue 31): SIGINT, SIGTERM and SIGHUP sent to ``mbh run``, SIGKILL sent
to it, and SIGKILL sent to one of its case workers, each at drawn moments (a fixed seed); after
each, no case is lost, none is stored twice, and the run (resumed where it stopped) holds the rows
of an uninterrupted run of the same campaign, case by case, apart from wall times.  A worker
killed under a running campaign leaves its case ``crashed``, a stored result that ``--resume``
keeps (docs/campaigns.md, "Stopping and resuming").  On Dask a stop kills the running cases'
processes."""

from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

import pandas as pd
import psutil
import pytest

from mbh._harness.run.executor import _dask_case, _end_dask_execution, execute
from mbh._harness.run.spec import load_campaign
from mbh._harness.store.manifest import list_runs

MBH = [sys.executable, "-m", "mbh._harness.cli"]

#: 18 cases of 4 s at small steps (0.2–2 s each on one core): with two workers the cases take
#: about three quarters of a run (the warm template's start the rest), so drawn moments fall
#: mostly between and during cases.
CAMPAIGN = """
timeout_s = 300.0
calibration = false

[[group]]
scenarios = ["fourbar"]
methods = { inhouse = ["rk4+direct", "rk4+none", "rkn4+direct", "rk4+baumgarte", "heun+direct",
                       "heun+none"] }
dts = [2e-4, 1e-4, 5e-5]
"""

#: Row columns that differ between two runs of the same cases: wall times and the run's id.
MACHINE_COLUMNS = ["wall_time_s", "wall_time_per_sim_s", "wall_time_per_step_s", "wall_times_s",
                   "run_id"]

#: Moments drawn per way of stopping (20 in all), as fractions of the uninterrupted run's
#: duration from its run folder's creation to its end.
MOMENTS_PER_WAY = 4
SEED = 31
WAYS = [("parent", signal.SIGINT), ("parent", signal.SIGTERM), ("parent", signal.SIGHUP),
        ("parent", signal.SIGKILL), ("worker", signal.SIGKILL)]
#: How long a process killed with its parent may take to go (the kernel kills it at once; the
#: margin covers a loaded machine), s.
DEATH_WAIT_S = 10.0


def drawn_moments() -> list[tuple[str, int, float]]:
    draw = random.Random(SEED)
    return [(target, signum, round(draw.random(), 3))
            for target, signum in WAYS for _ in range(MOMENTS_PER_WAY)]


def moment_id(moment) -> str:
    target, signum, fraction = moment
    return f"{signal.Signals(signum).name}-{target}-{fraction}"


@dataclass(frozen=True)
class Baseline:
    campaign: Path
    rows: pd.DataFrame  # comparable rows of the uninterrupted run, by case_id
    duration_s: float  # run folder's creation to the run's end


def mbh_env(root: Path) -> dict:
    return os.environ | {"MBH_RESULTS_DIR": str(root)}


def start_mbh(campaign: Path, root: Path, *extra: str) -> subprocess.Popen:
    # SIGINT's default disposition, as an interactive run has (a shell starting a background job
    # would have it ignored there).
    return subprocess.Popen([*MBH, "run", str(campaign), "--workers", "2", "--quiet", *extra],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=mbh_env(root),
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))


def the_run(root: Path) -> dict:
    (manifest,) = list_runs(root)
    return manifest


def comparable_rows(root: Path, run_id: str) -> pd.DataFrame:
    """The run's ``cases.parquet`` without the machine-dependent columns, by case_id."""
    # Nullable types: an integer column holding a crashed row's None stays integer.
    rows = pd.read_parquet(root / run_id / "cases.parquet", dtype_backend="numpy_nullable")
    assert rows["case_id"].is_unique
    # Columns in name order: a run's columns come in the order its first stored rows had them.
    return rows.drop(columns=MACHINE_COLUMNS).set_index("case_id").sort_index().sort_index(axis=1)


@pytest.fixture(scope="module")
def baseline(tmp_path_factory) -> Baseline:
    folder = tmp_path_factory.mktemp("baseline")
    campaign = folder / "stoppable.toml"
    campaign.write_text(CAMPAIGN)
    run = start_mbh(campaign, folder / "results")
    _, err = run.communicate(timeout=900)
    assert run.returncode == 0, err
    manifest = the_run(folder / "results")
    duration = (datetime.fromisoformat(manifest["ended"])
                - datetime.fromisoformat(manifest["started"])).total_seconds()
    rows = comparable_rows(folder / "results", manifest["run_id"])
    assert (rows["status"] == "ok").all()
    return Baseline(campaign, rows, duration)


def wait_for_run_folder(run: subprocess.Popen, root: Path) -> None:
    for _ in range(60000):  # the run folder exists: the signal handlers are in place
        if list(root.glob("*/manifest.json")) or run.poll() is not None:
            return
        time.sleep(0.01)


def case_workers(run: subprocess.Popen) -> list[psutil.Process]:
    """The running case processes of ``run``: its descendants leading a process group of their
    own (the warm template and the fork server stay in the campaign's group)."""
    workers = []
    for child in psutil.Process(run.pid).children(recursive=True):
        try:
            if os.getpgid(child.pid) == child.pid and child.status() != psutil.STATUS_ZOMBIE:
                workers.append(child)
        except (ProcessLookupError, psutil.NoSuchProcess):
            continue
    return workers


def kill_a_worker(run: subprocess.Popen, draw: random.Random) -> bool:
    """SIGKILL one running case process of ``run`` as soon as there is one; False if the run
    ended first.  The process is stopped first and killed only once it shows stopped: one that
    had begun to exit between :func:`case_workers` and the kill ignored the signal, ended with 0
    and left no ``crashed`` row (a CI run's slow suite drew such a process at the moment 0.94,
    when the last cases end)."""
    while run.poll() is None:
        workers = case_workers(run)
        if workers:
            worker = draw.choice(workers)
            try:
                worker.send_signal(signal.SIGSTOP)
                if stopped(worker):
                    worker.send_signal(signal.SIGKILL)
                    return True
                worker.send_signal(signal.SIGCONT)  # not stopped: exiting, or never to be
            except psutil.NoSuchProcess:
                pass
        time.sleep(0.005)
    return False


def stopped(process: psutil.Process) -> bool:
    """Whether ``process``, sent SIGSTOP, shows stopped within :data:`DEATH_WAIT_S` (False as
    soon as it shows ended: it was exiting, and a stop or a kill no longer reaches it)."""
    deadline = time.monotonic() + DEATH_WAIT_S
    while time.monotonic() < deadline:
        status = process.status()
        if status == psutil.STATUS_STOPPED:
            return True
        if status in (psutil.STATUS_ZOMBIE, psutil.STATUS_DEAD):
            return False
        time.sleep(0.001)
    return False


def assert_all_gone(processes: list[psutil.Process]) -> None:
    """Every process of ``processes`` ends (or is a zombie) within :data:`DEATH_WAIT_S`; any
    left is killed and named."""
    _, alive = psutil.wait_procs(processes, timeout=DEATH_WAIT_S)
    alive = [p for p in alive if p.is_running() and p.status() != psutil.STATUS_ZOMBIE]
    for process in alive:
        process.kill()
    assert not alive, f"still running after {DEATH_WAIT_S:g} s: {[p.pid for p in alive]}"


@pytest.mark.slow
@pytest.mark.parametrize("moment", drawn_moments(), ids=moment_id)
def test_a_stopped_run_resumes_to_the_rows_of_an_uninterrupted_run(tmp_path, baseline, moment):
    target, signum, fraction = moment
    root = tmp_path / "results"
    run = start_mbh(baseline.campaign, root)
    try:
        wait_for_run_folder(run, root)
        time.sleep(fraction * baseline.duration_s)
        sent = run.poll() is None  # else the run ended before the moment
        descendants = psutil.Process(run.pid).children(recursive=True) if sent else []
        killed_worker = False
        if target == "worker":
            killed_worker = kill_a_worker(run, random.Random(f"{SEED}-{fraction}"))
        elif sent:
            run.send_signal(signum)
        _, err = run.communicate(timeout=900)
    finally:
        run.kill()
    manifest = the_run(root)
    status = manifest["status"]

    if target == "worker" or not sent:  # the campaign went on: a killed case is a crashed row
        assert run.returncode == 0 and status == "complete", err
    elif signum == signal.SIGKILL:  # no handler: the run is left as it was, its workers die
        assert run.returncode == -signal.SIGKILL
        assert status in ("running", "complete")
        assert_all_gone(descendants)
    elif status == "interrupted":
        assert run.returncode == 128 + signum, err
        assert f"--resume {manifest['run_id']}" in err
    else:  # the signal came after the run completed, when mbh was printing or exiting
        assert status == "complete" and run.returncode in (0, -signum), err

    if status != "complete":
        resumed = subprocess.run([*MBH, "run", str(baseline.campaign), "--resume",
                                  manifest["run_id"], "--quiet"], capture_output=True, text=True,
                                 timeout=900, env=mbh_env(root))
        assert resumed.returncode == 0, resumed.stderr
        assert the_run(root)["status"] == "complete"

    rows = comparable_rows(root, manifest["run_id"])
    ids = {case.case_id for case in load_campaign(baseline.campaign).cases}
    assert set(rows.index) == ids  # none lost
    assert len(list((root / manifest["run_id"] / "cases").glob("part-*.parquet"))) == len(ids)
    crashed = rows.index[rows["status"] == "crashed"]
    assert len(crashed) == int(killed_worker), (rows.loc[crashed, "reason"].to_dict(), err)
    assert rows.loc[crashed, "reason"].str.startswith("worker process killed by SIGKILL").all()
    kept = rows.index.difference(crashed)
    pd.testing.assert_frame_equal(rows.loc[kept], baseline.rows.loc[kept], check_exact=True)


# --- Dask ------------------------------------------------------------------------------------

@dataclass(frozen=True)
class SleepSpec:
    """A toy case for the executor: sleeps (``pid_file`` set) or returns at once."""

    name: str
    pid_file: str = ""
    timeout_s: float = 600.0


def sleep_work(spec: SleepSpec):
    if spec.pid_file:  # written whole, then renamed: a reader that sees the file sees the pid
        Path(spec.pid_file + ".part").write_text(str(os.getpid()))
        os.replace(spec.pid_file + ".part", spec.pid_file)
        time.sleep(600)
    return {"name": spec.name, "status": "ok"}, None


def sleep_failure_row(spec: SleepSpec, status: str, reason: str) -> dict:
    return {"name": spec.name, "status": status, "reason": reason}


def test_a_stop_on_dask_kills_the_running_cases_processes(tmp_path):
    distributed = pytest.importorskip("distributed")
    sleepers = [SleepSpec(f"sleep-{i}", str(tmp_path / f"{i}.pid")) for i in range(2)]
    stored = []

    def stop_once_both_sleep(spec, row, trajectory):
        stored.append(spec.name)
        for _ in range(600):  # both sleepers are inside their case (pid written), within 60 s
            if all(Path(sleeper.pid_file).exists() for sleeper in sleepers):
                break
            time.sleep(0.1)
        raise KeyboardInterrupt

    with distributed.LocalCluster(n_workers=1, threads_per_worker=3, processes=True,
                                  host="127.0.0.1", dashboard_address=":0") as cluster:
        with pytest.raises(KeyboardInterrupt):
            execute([*sleepers, SleepSpec("quick")], sleep_work, failure_row=sleep_failure_row,
                    scheduler=cluster.scheduler_address, progress=False,
                    on_result=stop_once_both_sleep)
        assert stored == ["quick"]
        pids = [int(Path(sleeper.pid_file).read_text()) for sleeper in sleepers]
        # Killed by the stop (without it they sleep 600 s), and reaped by their Dask task.
        assert_all_gone([psutil.Process(pid) for pid in pids if psutil.pid_exists(pid)])


def test_a_dask_task_of_a_stopped_execution_starts_no_case(tmp_path):
    """A task the cancel did not reach before the stop gets a row, not a process."""
    _end_dask_execution("stopped-test-execution", stop=True)
    spec = SleepSpec("late", str(tmp_path / "late.pid"))
    row, trajectory = _dask_case("stopped-test-execution", sleep_work, spec, 60.0,
                                 sleep_failure_row)
    assert row["status"] == "crashed" and "stopped before the case started" in row["reason"]
    assert trajectory is None and not Path(spec.pid_file).exists()
