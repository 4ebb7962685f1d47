"""Run campaign cases, each in a worker process of its own, locally or on a Dask cluster.

Every case runs in its own Python process (:func:`run_isolated`), with one BLAS/OpenMP/numba
thread (:data:`WORKER_ENV`, set before anything imports numpy), in a process group of its own:

* warm (local default): forked by :mod:`multiprocessing`'s fork server from a template process
  that has imported numpy, scipy, the harness and the engines and loaded the compiled in-house
  kernels once (:mod:`mbh._harness.run.warm`); a case's process starts in ~0.05 s instead of the
  1–3 s of a fresh interpreter (``benchmarks/worker_start.py`` measures both side by side);
* cold: a fresh interpreter per case (``python -m mbh._harness.run.executor``), as on Dask, where a
  worker process may not fork children of its own.

Either way a worker dies with its parent: the kernel kills it when the process that started it
dies (:func:`die_with_parent`; a warm worker's parent is the fork server, which exits with the
campaign's process), so a campaign killed by SIGKILL leaves no case running.  What can go wrong in
an engine becomes a row and never ends the campaign:

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
them).  Ctrl-C (KeyboardInterrupt, and the stop signals the campaign turns into one) stops
submitting, kills the running children and is re-raised after every finished case has been handed
over.  Locally the children are killed through :class:`WorkerProcesses`.  On Dask the waiting
tasks are cancelled and every Dask worker is asked (``Client.run``, outside the task queue) to
kill the children of this execution's running tasks: each task registers its child under the
execution's id in its Dask worker process (:func:`_dask_case`), so a stop reaches exactly this
execution's cases, never another client's.  Dask itself cannot interrupt a running task; killing
its child ends the task at once (its ``crashed`` row is discarded).  A client killed by SIGKILL
cannot ask: the cases then running on the cluster finish there and their results are dropped.
"""

from __future__ import annotations

import contextlib
import ctypes
import faulthandler
import json
import multiprocessing
import multiprocessing.connection
import multiprocessing.forkserver
import os
import pickle
import signal
import subprocess
import sys
import tempfile
import threading
import traceback
import uuid
from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor, as_completed
from pathlib import Path

from mbh._harness.common import waits
from mbh._harness.common.status import CaseStatus
from mbh._harness.common.progress import CaseProgress, progress_wanted

#: Environment of every worker process: one thread per BLAS/OpenMP/numba pool, so timed cases
#: running side by side do not compete for cores.
WORKER_ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
              "NUMBA_NUM_THREADS": "1"}
#: Characters of a dead worker's last output kept in its row's reason.
OUTPUT_TAIL = 600
#: Environment variable by which :meth:`WorkerProcesses.start_template` tells the template which
#: scenarios to read before its first fork: a JSON list of names or paths.
WARM_SCENARIOS_ENV = "MBH_WARM_SCENARIOS"
#: Environment variable by which :meth:`WorkerProcesses.start_template` tells the template which
#: methods to run once before its first fork: a JSON list of [scenario, adapter, method, dt].
WARM_METHODS_ENV = "MBH_WARM_METHODS"
#: Environment variable by which :meth:`WorkerProcesses.start_template` tells the template for
#: which of its scenarios to compute, before its first fork, the reference's conditioning that
#: labels a failed case (:func:`mbh._harness.measure.failure_label.reference_conditioning`): a
#: JSON list of names or paths.
WARM_CONDITIONED_ENV = "MBH_WARM_CONDITIONED"
#: Environment variable by which :meth:`WorkerProcesses.start_template` tells the template to say
#: its waits on stderr (its compilations on a machine where the kernels are not compiled yet), as
#: the starting process does: "1", or empty for silence (``--quiet``).
WARM_SAY_ENV = "MBH_WARM_SAY"


@contextlib.contextmanager
def _environment(values: dict[str, str]):
    """Within the block, ``os.environ`` holds ``values`` too; restored after it."""
    previous = {key: os.environ.get(key) for key in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for key, value in previous.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value


def usable_cores() -> int:
    """Cores this process may run on (its CPU affinity), the default number of workers."""
    return len(os.sched_getaffinity(0))


class _Stopped(Exception):
    """The executor was interrupted; no new worker may start."""


# --- dying with the parent ------------------------------------------------------------------

# Why the kernel's parent-death signal and not process-group supervision: each worker has a
# process group of its own (so a timeout kills everything the case started, and Ctrl-C at a
# terminal reaches the campaign, not the engines), so killing "the campaign's group" cannot reach
# it; and a supervisor process that kills the workers when the campaign dies is one more process
# that SIGKILL can take down too.  PR_SET_PDEATHSIG is delivered by the kernel itself, whatever
# killed the parent.  It fires when the *thread* that started the worker ends: a cold worker's
# starting thread waits for it (run_isolated), a warm worker's is the fork server's only thread,
# so neither ends before its worker unless its process dies.  The check after the request closes
# the race with a parent that died first; an orphan adopted by a subreaper other than init (a
# ``systemd --user`` session) escapes the ``parent is None`` check, for the instant between its
# fork and the request.
_PR_SET_PDEATHSIG = 1


def die_with_parent(parent: int | None) -> None:
    """Have the kernel SIGKILL this process when its parent dies (Linux ``prctl``
    PR_SET_PDEATHSIG), so a campaign killed by SIGKILL leaves no case running; then exit at once
    if the parent is already gone (it died before the request took effect): ``parent`` is its pid
    as the parent knew it, or None to check only that the process was not adopted by init.
    Elsewhere (no ``prctl``) a worker outlives a killed parent until its case ends."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    except (OSError, AttributeError):
        return
    if os.getppid() == 1 or (parent is not None and os.getppid() != parent):
        os._exit(signal.SIGKILL + 128)


# --- worker processes -----------------------------------------------------------------------

class _ColdWorker:
    """A case in a fresh interpreter (``python -m mbh._harness.run.executor RESULT PARENT``, the work
    sent on stdin, :data:`WORKER_ENV`, its own process group, output captured)."""

    def __init__(self, work: Callable, spec, result_path: Path):
        self._payload = pickle.dumps((list(sys.path), pickle.dumps((work, spec))))
        self.process = subprocess.Popen(
            [sys.executable, "-m", "mbh._harness.run.executor", str(result_path), str(os.getpid())],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
            env=os.environ | WORKER_ENV, process_group=0)
        self._output = b""

    def wait(self, timeout_s: float) -> int:
        """The exit code (negative: the signal); raises subprocess.TimeoutExpired."""
        self._output, _ = self.process.communicate(self._payload, timeout=timeout_s)
        return self.process.returncode

    def kill(self) -> None:
        _kill_group(self.process.pid)

    def output(self) -> bytes:
        """What the worker printed (after :meth:`wait`, or after :meth:`kill` to reap it)."""
        if self.process.returncode is None:
            self._output, _ = self.process.communicate()
        return self._output


#: Held around every start of a forked worker and every read of its exit code, in every thread.
#: The fork server sends a child's exit code down a pipe that can be read once, and
#: multiprocessing polls every live child from whichever thread starts the next process
#: (``Process.start``).  Two threads could then read the same pipe at once, and the one left with
#: nothing reported exit code 255 for a case that had finished: a stray ``crashed`` row, seen in
#: CI under load.
_POLL_LOCK = threading.Lock()


class _ForkedWorker:
    """A case in a process forked from the warm template (:mod:`mbh._harness.run.warm`), output to a
    file beside the result, in a process group of its own, with this process's working folder,
    environment (plus :data:`WORKER_ENV`) and ``sys.path`` as they are now, not as they were when
    the template started.

    Its start and every read of its exit code hold :data:`_POLL_LOCK`.
    """

    def __init__(self, context, work: Callable, spec, result_path: Path):
        self._output_path = result_path.with_name("output.txt")
        here = (os.getcwd(), dict(os.environ) | WORKER_ENV, list(sys.path))
        self.process = context.Process(target=_forked_main, name="mbh-case",
                                       args=(str(result_path), str(self._output_path), here,
                                             work, spec))
        with _POLL_LOCK:
            self.process.start()

    def _exit_code(self, timeout_s: float | None) -> int | None:
        """The exit code once the process has ended (negative: the signal), or None if it still
        runs after ``timeout_s`` (None: wait for the end)."""
        if not multiprocessing.connection.wait([self.process.sentinel], timeout_s):
            return None
        with _POLL_LOCK:
            return self.process.exitcode

    def wait(self, timeout_s: float) -> int:
        code = self._exit_code(timeout_s)
        if code is None:
            raise subprocess.TimeoutExpired("mbh-case", timeout_s)
        return code

    def kill(self) -> None:
        _kill_group(self.process.pid)

    def output(self) -> bytes:
        self._exit_code(None)
        try:
            return self._output_path.read_bytes()
        except OSError:
            return b""


class WorkerProcesses:
    """Starts the worker of every case of one execution, warm (forked from a template process
    that has already imported and loaded everything: :mod:`mbh._harness.run.warm`) or cold (a fresh
    interpreter), and kills them all on an interrupt.

    Parameters
    ----------
    warm : bool
        Fork workers from the warm template.  If the template cannot start (or a fork fails),
        the workers start cold and a note on stderr says so once.
    """

    _context = None  # the fork server's context, shared by every execution of this process

    def __init__(self, warm: bool = True):
        self._lock = threading.Lock()
        self._running: set = set()
        self._closed = False
        self.warm = warm

    @classmethod
    def _fork_context(cls):
        if cls._context is None:
            cls._context = multiprocessing.get_context("forkserver")
            cls._context.set_forkserver_preload(["mbh._harness.run.warm"])
        return cls._context

    @classmethod
    def start_template(cls, scenarios: Iterable[str] = (),
                       methods: Iterable[tuple[str, str, str, float]] = (),
                       conditioned: Iterable[str] = ()) -> bool:
        """Start the warm template now, in the background, so that its imports and warm-up
        (~1.5–1.8 s) overlap the caller's own preparation instead of delaying the first case.
        The template also reads ``scenarios`` (names or paths) and their stored references once,
        for every case forked from it (:data:`WARM_SCENARIOS_ENV`), and runs each of ``methods``
        ((scenario, adapter, method, dt s): one per method of the campaign) for a few steps, so
        that what a method loads on its first run (compiled loops and kernels, an engine's
        libraries) is loaded once rather than in every case (:data:`WARM_METHODS_ENV`), and
        computes the failure label's conditioning of the references of ``conditioned``, a subset
        of ``scenarios`` (:data:`WARM_CONDITIONED_ENV`).  A
        template that is already running is kept as it is; one that cannot start is left to
        :meth:`start`, which says so.  Returns whether a template started now (so that this
        process has time to spare)."""
        cls._fork_context()
        server = multiprocessing.forkserver._forkserver
        before = getattr(server, "_forkserver_pid", None)
        told = {WARM_SCENARIOS_ENV: json.dumps(sorted(set(scenarios))),
                WARM_METHODS_ENV: json.dumps([list(method) for method in methods]),
                WARM_CONDITIONED_ENV: json.dumps(sorted(set(conditioned))),
                WARM_SAY_ENV: "1" if waits.shown_on_stderr() else ""}
        with contextlib.suppress(OSError, EOFError, ValueError), _environment(told):
            multiprocessing.forkserver.ensure_running()
            return getattr(server, "_forkserver_pid", None) not in (None, before)
        return False

    def start(self, work: Callable, spec, result_path: Path):
        """Start the worker of one case.  Raises _Stopped after :meth:`close`."""
        with self._lock:
            if self._closed:
                raise _Stopped
            worker = None
            if self.warm:
                try:
                    worker = _ForkedWorker(self._fork_context(), work, spec, result_path)
                except (OSError, EOFError, ValueError) as error:
                    self.warm = False
                    print(f"mbh: warm workers unavailable ({type(error).__name__}: {error}); "
                          f"cases start in fresh interpreters", file=sys.stderr)
            if worker is None:
                worker = _ColdWorker(work, spec, result_path)
            self._running.add(worker)
            return worker

    def finished(self, worker) -> None:
        with self._lock:
            self._running.discard(worker)

    def close(self) -> None:
        """Kill every running worker and refuse new ones."""
        with self._lock:
            self._closed = True
            for worker in self._running:
                worker.kill()


def _kill_group(pid: int) -> None:
    """SIGKILL a worker's whole process group (anything it started dies with it), or the worker
    alone if it has not made its group yet."""
    for kill in (os.killpg, os.kill):
        try:
            kill(pid, signal.SIGKILL)
            return
        except ProcessLookupError:
            continue


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
    lines = output.decode(errors="replace").strip().splitlines()
    # faulthandler ends a crash report with every loaded extension module (one line of a few
    # thousand characters in a warm worker): not why it died.
    text = "\n".join(line for line in lines if not line.startswith("Extension modules:"))
    report = text.find("Fatal Python error")
    # A crash report's head (the error, then the innermost frames first); else the last output.
    tail = text[report:report + OUTPUT_TAIL] if report >= 0 else text[-OUTPUT_TAIL:]
    return f"{what}; its last output: {tail}" if tail else what


def run_isolated(work: Callable, spec, timeout_s: float, failure_row: Callable,
                 workers: WorkerProcesses | None = None) -> tuple[dict, object]:
    """Run ``work(spec)`` in a process of its own and return its ``(row, trajectory)``.

    Parameters
    ----------
    work : callable
        ``work(spec) -> (row, trajectory)``; importable by name (a module-level function or an
        instance of a module-level class), since the child unpickles it.
    spec : CaseSpec
        The case (picklable).
    timeout_s : float
        Wall-clock limit of the whole child, its start included, s.
    failure_row : callable
        ``failure_row(spec, status, reason) -> row`` for a case that gave no result
        (:func:`mbh._harness.run.row.error_row`).
    workers : WorkerProcesses, optional
        Registry the child is started through (an interrupt kills it there); default: a cold
        worker of its own (a Dask task, one-off callers).

    Returns
    -------
    (dict, Trajectory or None)
        The work's row and trajectory; or a ``timeout``/``crashed`` row and None.
    """
    workers = workers or WorkerProcesses(warm=False)
    with tempfile.TemporaryDirectory(prefix="mbh-case-") as folder:
        result_path = Path(folder) / "result.pickle"
        worker = workers.start(work, spec, result_path)
        try:
            returncode = worker.wait(timeout_s)
        except subprocess.TimeoutExpired:
            worker.kill()
            worker.output()
            return failure_row(spec, CaseStatus.TIMEOUT, f"no result within the case timeout of "
                                                f"{timeout_s:g} s; worker process killed"), None
        finally:
            workers.finished(worker)
        if returncode != 0 or not result_path.exists():
            reason = _exit_reason(returncode, worker.output())
            return failure_row(spec, CaseStatus.CRASHED, reason), None
        kind, value = pickle.loads(result_path.read_bytes())
    if kind == "raised":
        return failure_row(spec, CaseStatus.CRASHED, f"worker raised {value}"), None
    return value


def _importable(name: str) -> bool:
    """Whether a fresh interpreter with this ``sys.path`` finds the top-level module ``name``
    (asked of the import finders themselves: ``sys.modules`` may hold a module imported by path,
    as pytest's ``--import-mode=importlib`` does, that no other process can import)."""
    return name in sys.builtin_module_names or any(
        finder.find_spec(name, None) is not None
        for finder in sys.meta_path if hasattr(finder, "find_spec"))


def why_not_sendable(value) -> str | None:
    """Why ``value`` (a class, or an instance of one) cannot reach a worker process, or None.

    A worker unpickles what it runs: a class travels by its importable name, so it must be
    defined at the top level of a module that a fresh interpreter on this ``sys.path`` imports
    (not in ``__main__``, the script being run, nor inside a function), and an instance must
    pickle.
    """
    cls = value if isinstance(value, type) else type(value)
    if "<locals>" in cls.__qualname__:
        return f"class {cls.__qualname__} is defined inside a function"
    if cls.__module__ == "__main__":
        return f"class {cls.__qualname__} is defined in the script being run (__main__)"
    if not _importable(cls.__module__.partition(".")[0]):
        return (f"module {cls.__module__} of class {cls.__qualname__} cannot be imported by "
                f"name from sys.path")
    try:
        pickle.dumps(value)
    except (pickle.PicklingError, TypeError, AttributeError) as error:
        return f"it does not pickle ({type(error).__name__}: {error})"
    return None


def _run_and_exit(result_path: str, load_case: Callable) -> None:
    """Worker side: ``work, spec = load_case()``, run, write the pickled ``("done", (row,
    trajectory))`` or ``("raised", message)`` atomically, exit at once."""
    faulthandler.enable()  # a segfault prints the Python stack into the captured output
    try:
        work, spec = load_case()
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


def _child_main(result_path: str, parent: str) -> None:
    """A cold worker: (sys.path, work, spec) from stdin."""
    die_with_parent(int(parent))
    sys_path, inner = pickle.loads(sys.stdin.buffer.read())
    sys.path[:0] = [entry for entry in sys_path if entry not in sys.path]
    _run_and_exit(result_path, lambda: pickle.loads(inner))


def _forked_main(result_path: str, output_path: str, here: tuple, work: Callable, spec) -> None:
    """A warm worker, forked from the template: its own process group, killed with the fork
    server (which exits with the campaign's process), output into ``output_path``, in the
    starting process's working folder, environment and ``sys.path`` (``here``)."""
    os.setpgid(0, 0)
    folder, environment, sys_path = here
    os.chdir(folder)
    os.environ.clear()
    os.environ.update(environment)
    sys.path[:0] = [entry for entry in sys_path if entry not in sys.path]
    # The fork server exits when every holder of its "alive" pipe's write end has gone; it hands
    # that end to each process it forks, so a running case would keep it (and itself) alive
    # after the campaign's death.  Dropping it lets the server exit and the kernel kill the case.
    alive = getattr(multiprocessing.forkserver._forkserver, "_forkserver_alive_fd", None)
    if alive is not None:
        os.close(alive)
    die_with_parent(None)
    output = os.open(output_path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    for stream in (1, 2):
        os.dup2(output, stream)
    _run_and_exit(result_path, lambda: (work, spec))


def _default_failure_row() -> Callable:
    from mbh._harness.run.row import error_row

    return error_row


def execute(specs: Iterable, work: Callable, *, workers: int | None = None,
            scheduler: str | None = None, timeout_s: float | None = None,
            on_result: Callable, progress: bool = True,
            failure_row: Callable | None = None, warm: bool = True) -> None:
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
        ``failure_row(spec, status, reason) -> row``; default :func:`mbh._harness.run.row.error_row`.
    warm : bool
        Local backend: fork each case's process from the warm template (default) rather than
        start a fresh interpreter (:class:`WorkerProcesses`).

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
            _run_local(specs, limits, work, workers or usable_cores(), failure_row, finished,
                       warm)
        else:
            _run_dask(specs, limits, work, scheduler, failure_row, finished)


def _run_local(specs, limits, work, workers, failure_row, finished, warm) -> None:
    processes = WorkerProcesses(warm)
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


#: The worker registries of the Dask executions whose tasks run in this process (a Dask worker),
#: by execution id: where :func:`_end_dask_execution` finds the children to kill.
_DASK_EXECUTIONS: dict[str, WorkerProcesses] = {}
_DASK_EXECUTIONS_LOCK = threading.Lock()


def _dask_case(execution: str, work: Callable, spec, timeout_s: float, failure_row: Callable):
    """A Dask task: :func:`run_isolated` with the child registered under ``execution`` in this
    Dask worker process; a case of an execution already stopped gets a ``crashed`` row (which
    its cancelled future drops) instead of a child."""
    with _DASK_EXECUTIONS_LOCK:
        workers = _DASK_EXECUTIONS.setdefault(execution, WorkerProcesses(warm=False))
    try:
        return run_isolated(work, spec, timeout_s, failure_row, workers)
    except _Stopped:
        return failure_row(spec, CaseStatus.CRASHED,
                           "the campaign stopped before the case started"), None


def _end_dask_execution(execution: str, stop: bool) -> None:
    """Run in every Dask worker process (``Client.run``) when an execution ends: with ``stop``,
    kill its running children and refuse its later tasks (the closed registry stays, so a task
    the cancel did not reach in time starts nothing); else forget its registry."""
    with _DASK_EXECUTIONS_LOCK:
        if not stop:
            _DASK_EXECUTIONS.pop(execution, None)
            return
        workers = _DASK_EXECUTIONS.setdefault(execution, WorkerProcesses(warm=False))
    workers.close()


def _run_dask(specs, limits, work, scheduler, failure_row, finished) -> None:
    from distributed import Client, KilledWorker
    from distributed import as_completed as dask_completed

    execution = uuid.uuid4().hex
    with Client(scheduler) as client:
        futures = {client.submit(_dask_case, execution, work, spec, limit, failure_row,
                                 pure=False): spec
                   for spec, limit in zip(specs, limits)}
        try:
            for future in dask_completed(futures):
                spec = futures[future]
                try:
                    row, trajectory = future.result()
                except KilledWorker as error:
                    row = failure_row(spec, CaseStatus.CRASHED, f"Dask worker died: {error}")
                    trajectory = None
                finished(spec, row, trajectory)
        except BaseException:
            client.cancel(list(futures))
            client.run(_end_dask_execution, execution, True, on_error="ignore")
            raise
        client.run(_end_dask_execution, execution, False, on_error="ignore")


if __name__ == "__main__":
    _child_main(sys.argv[1], sys.argv[2])
