"""Run campaign cases, each in a fresh worker process, locally or on a Dask cluster.

Every case runs in its own Python process (:func:`run_isolated`): a child interpreter started for
that case alone, with one BLAS/OpenMP/numba thread (:data:`WORKER_ENV`, set in its environment
before anything imports numpy), in a process group of its own.  What can go wrong in an engine
therefore becomes a row and never ends the campaign:

* the case outlives its wall-clock limit → its process group is killed, status ``timeout``;
* the process dies (SIGKILL from the kernel's OOM killer, a segfault, an abort) or exits without a
  result → status ``crashed``, the reason naming the signal or exit code and the last output;
* the work function raises (MemoryError included) → status ``crashed`` with the exception.

Two backends hand cases to :func:`run_isolated`:

* local (default): a thread per worker slot, each starting one child process per case, so at
  most ``workers`` cases run at once;
* Dask: ``scheduler="tcp://HOST:PORT"`` connects a ``distributed.Client`` to an existing cluster
  (or a ``LocalCluster``'s address) and submits one task per case; the task runs the case in a
  child of the Dask worker, so timeouts and crashes are handled there in the same way and the Dask
  worker survives.  A Dask worker that dies anyway (``KilledWorker``) gives a ``crashed`` row.
  How many cases run at once is the cluster's thread count: give it one thread per core.

Results are handed to ``on_result`` in the calling process as they finish (the caller stores
them).  Ctrl-C (KeyboardInterrupt) stops submitting, kills the running local children (Dask tasks
are cancelled; a case already running on a cluster finishes there and is discarded), and is
re-raised after every finished case has been handed over.
"""

from __future__ import annotations

import faulthandler
import os
import pickle
import signal
import subprocess
import sys
import tempfile
import threading
import traceback
from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor, as_completed
from pathlib import Path

from harness.common.progress import CaseProgress, progress_wanted

#: Environment of every worker process: one thread per BLAS/OpenMP/numba pool, so timed cases
#: running side by side do not compete for cores.
WORKER_ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
              "NUMBA_NUM_THREADS": "1"}
#: Characters of a dead worker's last output kept in its row's reason.
OUTPUT_TAIL = 600


def usable_cores() -> int:
    """Cores this process may run on (its CPU affinity), the default number of workers."""
    return len(os.sched_getaffinity(0))


class _Stopped(Exception):
    """The executor was interrupted; no new worker may start."""


class WorkerProcesses:
    """The running worker processes of one execution, so that an interrupt can end them all."""

    def __init__(self):
        self._lock = threading.Lock()
        self._running: set[subprocess.Popen] = set()
        self._closed = False

    def start(self, command: list[str]) -> subprocess.Popen:
        """Start a worker (its own process group, :data:`WORKER_ENV`, output captured).

        Raises _Stopped after :meth:`close`.
        """
        with self._lock:
            if self._closed:
                raise _Stopped
            process = subprocess.Popen(command, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                       stderr=subprocess.STDOUT, env=os.environ | WORKER_ENV,
                                       process_group=0)
            self._running.add(process)
            return process

    def finished(self, process: subprocess.Popen) -> None:
        with self._lock:
            self._running.discard(process)

    def close(self) -> None:
        """Kill every running worker and refuse new ones."""
        with self._lock:
            self._closed = True
            for process in self._running:
                _kill(process)


def _kill(process: subprocess.Popen) -> None:
    """SIGKILL the worker's whole process group (anything it started dies with it)."""
    try:
        os.killpg(process.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass


def _exit_reason(returncode: int, output: bytes) -> str:
    """Why a worker that produced no result ended: signal or exit code, and its last output."""
    if returncode < 0:
        try:
            name = signal.Signals(-returncode).name
        except ValueError:
            name = f"signal {-returncode}"
        what = f"worker process killed by {name}"
    else:
        what = f"worker process exited with code {returncode} without a result"
    tail = output.decode(errors="replace").strip()[-OUTPUT_TAIL:]
    return f"{what}; its last output: {tail}" if tail else what


def run_isolated(work: Callable, spec, timeout_s: float, failure_row: Callable,
                 workers: WorkerProcesses | None = None) -> tuple[dict, object]:
    """Run ``work(spec)`` in a fresh child process and return its ``(row, trajectory)``.

    Parameters
    ----------
    work : callable
        ``work(spec) -> (row, trajectory)``; importable by name (a module-level function or an
        instance of a module-level class), since the child unpickles it.
    spec : CaseSpec
        The case (picklable).
    timeout_s : float
        Wall-clock limit of the whole child, interpreter start included, s.
    failure_row : callable
        ``failure_row(spec, status, reason) -> row`` for a case that gave no result
        (:func:`harness.run.row.error_row`).
    workers : WorkerProcesses, optional
        Registry the child is started through (an interrupt kills it there).

    Returns
    -------
    (dict, Trajectory or None)
        The work's row and trajectory; or a ``timeout``/``crashed`` row and None.
    """
    workers = workers or WorkerProcesses()
    with tempfile.TemporaryDirectory(prefix="mbh-case-") as folder:
        result_path = Path(folder) / "result.pickle"
        payload = pickle.dumps((list(sys.path), pickle.dumps((work, spec))))
        process = workers.start([sys.executable, "-m", "harness.run.executor", str(result_path)])
        try:
            output, _ = process.communicate(payload, timeout=timeout_s)
        except subprocess.TimeoutExpired:
            _kill(process)
            process.communicate()
            return failure_row(spec, "timeout", f"no result within the case timeout of "
                                                f"{timeout_s:g} s; worker process killed"), None
        finally:
            workers.finished(process)
        if process.returncode != 0 or not result_path.exists():
            return failure_row(spec, "crashed", _exit_reason(process.returncode, output)), None
        kind, value = pickle.loads(result_path.read_bytes())
    if kind == "raised":
        return failure_row(spec, "crashed", f"worker raised {value}"), None
    return value


def _child_main(result_path: str) -> None:
    """Worker side of :func:`run_isolated`: read (sys.path, work, spec) from stdin, run, write the
    pickled ``("done", (row, trajectory))`` or ``("raised", message)`` atomically, exit at once."""
    faulthandler.enable()  # a segfault prints the Python stack into the captured output
    sys_path, inner = pickle.loads(sys.stdin.buffer.read())
    sys.path[:0] = [entry for entry in sys_path if entry not in sys.path]
    try:
        work, spec = pickle.loads(inner)
        data = pickle.dumps(("done", work(spec)))
    except BaseException as error:  # noqa: BLE001 — every failure of the case becomes its row
        last = traceback.extract_tb(error.__traceback__)[-1:] or [None]
        where = f" (at {last[0].filename}:{last[0].lineno})" if last[0] else ""
        data = pickle.dumps(("raised", f"{type(error).__name__}: {error}{where}"))
    temporary = Path(result_path).with_suffix(".tmp")
    temporary.write_bytes(data)
    os.replace(temporary, result_path)
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)  # skip interpreter teardown: some engine libraries hang or crash in it


def _default_failure_row() -> Callable:
    from harness.run.row import error_row

    return error_row


def execute(specs: Iterable, work: Callable, *, workers: int | None = None,
            scheduler: str | None = None, timeout_s: float | None = None,
            on_result: Callable, progress: bool = True,
            failure_row: Callable | None = None) -> None:
    """Run every spec in its own worker process and hand each result to ``on_result``.

    Parameters
    ----------
    specs : iterable of CaseSpec
    work : callable
        ``work(spec) -> (row, trajectory)``, run in the worker (see :func:`run_isolated`).
    workers : int, optional
        Local backend: cases at once (default :func:`usable_cores`).  Ignored with a scheduler.
    scheduler : str, optional
        Address of a Dask scheduler (``tcp://HOST:PORT``); None runs locally.
    timeout_s : float, optional
        Per-case wall-clock limit, s; default each spec's own ``timeout_s``.
    on_result : callable
        ``on_result(spec, row, trajectory)``, called in this process as each case finishes
        (trajectory None for a ``timeout``/``crashed`` row).
    progress : bool
        Draw the progress bar (only when stderr is a terminal).
    failure_row : callable, optional
        ``failure_row(spec, status, reason) -> row``; default :func:`harness.run.row.error_row`.

    Raises
    ------
    KeyboardInterrupt
        On Ctrl-C, after killing the running workers; the cases handed over so far are complete.
    """
    specs = list(specs)
    failure_row = failure_row or _default_failure_row()
    limits = [spec.timeout_s if timeout_s is None else timeout_s for spec in specs]
    with CaseProgress(len(specs), progress_wanted(progress)) as bar:
        def finished(spec, row, trajectory):
            on_result(spec, row, trajectory)
            bar.update(row)

        if scheduler is None:
            _run_local(specs, limits, work, workers or usable_cores(), failure_row, finished)
        else:
            _run_dask(specs, limits, work, scheduler, failure_row, finished)


def _run_local(specs, limits, work, workers, failure_row, finished) -> None:
    processes = WorkerProcesses()
    pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="mbh-worker")
    futures = {pool.submit(run_isolated, work, spec, limit, failure_row, processes): spec
               for spec, limit in zip(specs, limits)}
    try:
        for future in as_completed(futures):
            finished(futures[future], *future.result())
    except BaseException:
        processes.close()
        pool.shutdown(wait=True, cancel_futures=True)
        raise
    pool.shutdown()


def _run_dask(specs, limits, work, scheduler, failure_row, finished) -> None:
    from distributed import Client, KilledWorker
    from distributed import as_completed as dask_completed

    with Client(scheduler) as client:
        futures = {client.submit(run_isolated, work, spec, limit, failure_row, pure=False): spec
                   for spec, limit in zip(specs, limits)}
        try:
            for future in dask_completed(futures):
                spec = futures[future]
                try:
                    row, trajectory = future.result()
                except KilledWorker as error:
                    row, trajectory = failure_row(spec, "crashed", f"Dask worker died: {error}"), None
                finished(spec, row, trajectory)
        except BaseException:
            client.cancel(list(futures))
            raise


if __name__ == "__main__":
    _child_main(sys.argv[1])
