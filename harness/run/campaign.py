"""Run a campaign into the result store: references, calibration, cases, stability sweep.

Stages of :func:`run_campaign`, in order:

1. every scenario's verified reference is loaded (or built) here, before any case starts, so the
   workers only read the cache; a refused reference (``ReferenceBuildError``) means that scenario's
   cases run without one (their rows say ``reference = "none: <reason>"``);
2. the run folder is created, or reopened with ``resume`` (its stored cases are skipped);
3. the machine-speed figure (:mod:`mbh._harness.common.machine_speed`: a fixed numpy and scipy
   workload) is measured in this process while the warm template starts, or else as the first
   case of the next stage (:mod:`mbh._harness.run.calibration`), and stored with the run (times of
   different runs compare as ratios to it);
4. the cases run through :func:`mbh._harness.run.executor.execute` (one fresh process each) and are stored
   as they finish; with ``reuse`` an identical case already in the :class:`~mbh._harness.store.runs.CaseCache`
   (same scenario content, engine version, method, step and duration, computed by the same code
   under the same bounds and accuracy) is copied instead of run, and every run case is offered
   to the cache;
5. the optional stability sweep (:mod:`mbh._harness.run.sweep`) runs through the same executor;
6. the run is marked ``complete``.

Timing hygiene: the local pool never runs more cases at once than this process has cores
(:func:`mbh._harness.run.executor.usable_cores`), and every worker has one BLAS/numba thread.  Ctrl-C, or
a stop signal (SIGTERM from a scheduler, a CI timeout or ``systemd``; SIGHUP from a closed
terminal: :data:`STOP_SIGNALS`), kills the running workers, marks the run ``interrupted`` (every
finished case stays stored) and raises :class:`CampaignInterrupted`; ``resume`` completes it.
"""

from __future__ import annotations

import collections
import contextlib
import dataclasses
import json
import signal
import sys
import threading

from mbh._harness.common.status import RunStatus
from mbh._harness.measure.failure_label import CONDITION_AHEAD_CASES
from mbh._harness.model import scenario
from mbh._harness.common.environment import code_fingerprint
from mbh._harness.run.calibration import (CALIBRATION, WithCalibration, calibration_work,
                                          store_figure)
from mbh._harness.run.row import CaseWork
from mbh._harness.run.executor import WorkerProcesses, execute, usable_cores, why_not_sendable
from mbh._harness.references.build import ReferenceBuildError, reference_trajectory
from mbh._harness.store.cache import CaseCache
from mbh._harness.store.runs import RunStore
from mbh._harness.store.writer_lock import RunLocked
from mbh._harness.run.sweep import bisections, stability_sweep
from mbh._harness.common.errors import MbhError


#: How long to wait for a Dask scheduler to answer, s.
SCHEDULER_CONNECT_S = 30.0


class RunnerError(MbhError, ValueError):
    """A run that cannot start as asked (bad worker count, unknown or mismatched run to resume)."""


#: Signals that stop a run the way Ctrl-C does.
STOP_SIGNALS = (signal.SIGTERM, signal.SIGHUP)


class StopSignal(KeyboardInterrupt):
    """A stop signal (:data:`STOP_SIGNALS`) received during a run, raised in the main thread as
    Ctrl-C raises KeyboardInterrupt, so every path that handles Ctrl-C handles it too."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


class CampaignInterrupted(KeyboardInterrupt):
    """Ctrl-C or a stop signal during a run; ``store`` is the run, marked ``interrupted``;
    ``signum`` the signal (SIGINT for Ctrl-C)."""

    def __init__(self, store: RunStore, signum: int = signal.SIGINT):
        super().__init__(f"run {store.run_id} interrupted by {signal.Signals(signum).name}")
        self.store = store
        self.signum = signum


@contextlib.contextmanager
def stop_signals_interrupt():
    """Within the block, :data:`STOP_SIGNALS` raise :class:`StopSignal` in the main thread; the
    previous handlers are restored after it.  Off the main thread (where Python cannot set
    handlers) nothing changes."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def stop(signum, _frame):
        raise StopSignal(signum)

    previous = {signum: signal.signal(signum, stop) for signum in STOP_SIGNALS}
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


def timed_workers(requested: int | None, say=print) -> int:
    """Worker count for timed cases: ``requested`` (default all cores), at most the cores."""
    cores = usable_cores()
    if requested is None:
        return cores
    if requested < 1:
        raise RunnerError(f"--workers must be at least 1, got {requested}")
    if requested > cores:
        say(f"mbh: {requested} workers asked for, {cores} used: timed cases never run more "
            f"at once than there are cores")
        return cores
    return requested


def prepare_references(names, say=print) -> None:
    """Load or build each scenario's verified reference in this process (into the reference
    cache the workers read); a refused one is reported through ``say``."""
    for name in sorted(set(names)):
        try:
            reference_trajectory(scenario.load(name))
        except ReferenceBuildError as error:
            say(f"mbh: {name}: no verified reference, its cases run without one ({error})")


def check_scheduler(address: str) -> None:
    """Connect to the Dask scheduler at ``address`` once, so a wrong address is an input error
    before the run folder exists."""
    from distributed import Client

    try:
        Client(address, timeout=SCHEDULER_CONNECT_S).close()
    except (OSError, TimeoutError, ValueError) as error:
        raise RunnerError(f"--scheduler {address}: cannot connect: {error}") from None


def _open_store(campaign, resume: str | None, root) -> RunStore:
    """The new run, or the run to resume, locked for this process (one writer per run)."""
    if resume is None:
        store = RunStore.create(campaign, root)
        store.lock()
        return store
    try:
        store = RunStore.open(resume, root)
        store.lock()
    except FileNotFoundError as error:
        raise RunnerError(f"--resume: {error}") from None
    except RunLocked as error:
        raise RunnerError(f"--resume {resume}: {error}") from None
    if store.manifest.get("campaign_text") != campaign.text:
        raise RunnerError(f"--resume {resume}: the run was started from a different campaign "
                         f"file than {campaign.path} (or the file changed since); resume it with "
                         f"the same file")
    store.mark_running()
    return store


def check_given_adapters(campaign) -> None:
    """Raise :class:`RunnerError` unless every adapter the campaign was given as a class or an
    instance (:attr:`~mbh._harness.run.spec.Campaign.given_adapters`) can reach the worker
    processes its cases run in (:func:`~mbh._harness.run.executor.why_not_sendable`)."""
    for name, adapter in campaign.given_adapters:
        problem = why_not_sendable(adapter)
        if problem:
            raise RunnerError(
                f"adapter {name!r} cannot reach the campaign's worker processes: {problem}. "
                f"Every case runs in a process of its own, which imports the adapter's class by "
                f"name: define it at the top level of a module on sys.path (beside your script, "
                f"not in it) and pass that class, or a picklable instance of it")


class _Recorder:
    """Stores each finished case (and offers it to the cache).

    ``keys`` maps scenario names to content hashes and adapter names to versions; ``settings``
    is the cache's last key part (:func:`_cache_settings`).  The cases of ``uncached`` adapters
    (given as classes or instances: their code is not in the cache key's fingerprint) are
    neither taken from the cache nor offered to it."""

    def __init__(self, store: RunStore, cache: CaseCache, keys: dict, settings: str,
                 uncached: frozenset[str] = frozenset()):
        self.store, self.cache, self.keys, self.settings = store, cache, keys, settings
        self.uncached = uncached

    def key(self, spec) -> tuple[str, str, str]:
        """(scenario content hash, adapter version, settings) of ``spec``, the cache's key
        parts."""
        return self.keys[spec.scenario], self.keys[spec.adapter], self.settings

    def record(self, spec, row: dict, trajectory) -> None:
        self.store.add(row, trajectory)
        if spec.adapter not in self.uncached:
            self.cache.put(spec, *self.key(spec), row, trajectory, run_id=self.store.run_id)

    def reuse(self, specs: list) -> list:
        """Store the cached cases among ``specs``; return the ones still to run."""
        remaining = []
        for spec in specs:
            found = None if spec.adapter in self.uncached else self.cache.lookup(
                spec, *self.key(spec))
            if found is None:
                remaining.append(spec)
            else:
                row, trajectory = found
                self.store.add({**row, "case_id": spec.case_id}, trajectory)
        return remaining


def first_runs(campaign) -> list[tuple[str, str, str, float]]:
    """(scenario, adapter, method, dt s) of the first case of each (adapter, method) of the
    campaign, its sweep's included, in the campaign's order: what the warm template runs once
    (:meth:`~mbh._harness.run.executor.WorkerProcesses.start_template`).  Adapters given as a class or an
    instance are left out (the template finds only registered ones)."""
    given = {name for name, _ in campaign.given_adapters}
    runs = {}
    for spec in campaign.cases:
        runs.setdefault((spec.adapter, spec.method), (spec.scenario, spec.dt))
    sweep = campaign.sweep
    if sweep is not None:
        for adapter, methods in sweep.methods.items():
            for method in methods:
                runs.setdefault((adapter, method), (sweep.scenarios[0], sweep.dt_max))
    return [(scene, adapter, method, dt) for (adapter, method), (scene, dt) in runs.items()
            if adapter not in given]


def _cache_keys(names: set[str], adapters: set[str]) -> dict[str, str]:
    """Content hashes of the scenarios and versions of the adapters (for an adapter that cannot
    be loaded, the reason: its cases become rows that say so)."""
    from mbh._adapters import version_or_problem

    keys = {name: scenario.load(name).content_hash for name in names}
    for name in adapters:
        version, problem = version_or_problem(name)
        keys[name] = version or problem
    return keys


def _cache_settings(campaign) -> str:
    """What a cached row depends on besides its case and engine: the harness's and adapters'
    code (:func:`~mbh._harness.common.environment.code_fingerprint`), the verdict's bounds and the accuracy
    the campaign judges ``accurate`` by; a row computed under other settings is not reused."""
    return json.dumps({"code": code_fingerprint(), "bounds": dataclasses.asdict(campaign.bounds),
                       "accuracy": campaign.accuracy}, sort_keys=True)


def _sweep(campaign, store: RunStore, work, workers, backend: dict, quiet: bool) -> None:
    """Run the campaign's stability sweep (searches with a stored row are skipped)."""
    from mbh._harness.run.spec import DEFAULT_TIMEOUT_S, CaseSpec

    # One repetition (only the status and the error matter); the campaign's longest case limit.
    timeout = max((spec.timeout_s for spec in campaign.cases), default=DEFAULT_TIMEOUT_S)

    def make_spec(scenario_name, adapter, method, dt):
        return CaseSpec(scenario_name, adapter, method, dt, campaign.sweep.t_end[scenario_name],
                        1, timeout)

    done = set(store.sweeps().get("sweep_id", []))
    searches = [search for search in bisections(campaign.sweep)
                if search.row()["sweep_id"] not in done]

    def run(specs):
        rows = {}
        execute(specs, work, workers=workers, **backend, progress=not quiet,
                on_result=lambda spec, row, trajectory: rows.__setitem__(spec.case_id, row))
        return rows

    stability_sweep(searches, make_spec, run, store.add_sweep)


def conditioned_ahead(campaign) -> set[str]:
    """The scenarios whose failure-label conditioning the warm template computes ahead: those
    with at least :data:`~mbh._harness.measure.failure_label.CONDITION_AHEAD_CASES` cases in
    ``campaign``."""
    counts = collections.Counter(spec.scenario for spec in campaign.cases)
    return {name for name, cases in counts.items() if cases >= CONDITION_AHEAD_CASES}


def run_campaign(campaign, *, workers: int | None = None, scheduler: str | None = None,
                 resume: str | None = None, reuse: bool = False, root=None, quiet: bool = False,
                 work=None, warm_workers: bool = True) -> RunStore:
    """Run ``campaign`` (a :class:`mbh._harness.run.spec.Campaign`) into the result store.

    Parameters
    ----------
    workers : int, optional
        Local worker processes (default and maximum: the cores).
    scheduler : str, optional
        Dask scheduler address; the cases then run on that cluster.
    resume : str, optional
        Run id of an interrupted run of the same campaign file to complete.
    reuse : bool
        Copy identical cases from the cache instead of running them.
    root : path, optional
        Results root (default :func:`mbh._harness.store.runs.results_root`).
    quiet : bool
        No progress bar and no notes on stderr (the campaign's
        :attr:`~mbh._harness.run.spec.Campaign.notes` are in the manifest's ``notes`` either way).
    work : callable, optional
        ``work(spec) -> (row, trajectory)`` run in the workers; default
        :class:`~mbh._harness.run.row.CaseWork` with the campaign's bounds, accuracy and given
        adapters.
    warm_workers : bool
        Locally, fork each case's process from the warm template (default) rather than start a
        fresh interpreter per case (:class:`mbh._harness.run.executor.WorkerProcesses`).

    Returns
    -------
    RunStore
        The run, status ``complete``.

    Raises
    ------
    CampaignInterrupted
        On Ctrl-C or a stop signal, with the run marked ``interrupted``.
    StopSignal
        On a stop signal before the run was stored (a KeyboardInterrupt, as Ctrl-C then).
    RunnerError
        A bad worker count, an unreachable scheduler, an unknown run to resume, a run of
        another campaign file, or an adapter given as a class or instance that cannot reach the
        worker processes (:func:`check_given_adapters`).
    """
    with stop_signals_interrupt():
        return _run_campaign(campaign, workers=workers, scheduler=scheduler, resume=resume,
                             reuse=reuse, root=root, quiet=quiet, work=work,
                             warm_workers=warm_workers)


def _run_campaign(campaign, *, workers, scheduler, resume, reuse, root, quiet, work,
                  warm_workers) -> RunStore:
    def say(text):
        if not quiet:
            print(text, file=sys.stderr)

    check_given_adapters(campaign)
    for note in campaign.notes:
        say(f"mbh: {note}")
    work = work or CaseWork(campaign.bounds, campaign.accuracy, campaign.given_adapters)
    if scheduler is None:
        workers = timed_workers(workers, say)
    else:
        check_scheduler(scheduler)
    RunStore.check_writable(root)  # before references are built: that can take minutes
    names = {spec.scenario for spec in campaign.cases}
    if campaign.sweep is not None:
        names |= set(campaign.sweep.scenarios)
    # The template's start overlaps the references' preparation and, when it starts now, the
    # calibration in this process (mbh._harness.run.calibration).
    template_starting = (scheduler is None and warm_workers
                         and WorkerProcesses.start_template(names, first_runs(campaign),
                                                            conditioned_ahead(campaign)))
    prepare_references(names, say)
    backend = {"scheduler": scheduler, "warm": warm_workers}
    store = _open_store(campaign, resume, root)
    store.manifest["notes"] = list(campaign.notes)  # written with the next manifest write
    try:
        calibrate = campaign.calibration and store.calibration_s is None
        if calibrate and template_starting:
            store_figure(store, calibration_work(CALIBRATION)[0], say)
            calibrate = False
        done = store.done_case_ids()
        todo = [spec for spec in campaign.cases if spec.case_id not in done]
        given = frozenset(name for name, _ in campaign.given_adapters)
        recorder = _Recorder(store, CaseCache(root), _cache_keys(
            {spec.scenario for spec in todo}, {spec.adapter for spec in todo} - given),
            _cache_settings(campaign), given)
        if reuse:
            todo = recorder.reuse(todo)

        def on_result(spec, row, trajectory):
            if spec == CALIBRATION:
                store_figure(store, row, say)
            else:
                recorder.record(spec, row, trajectory)

        execute([CALIBRATION, *todo] if calibrate else todo,
                WithCalibration(work) if calibrate else work, workers=workers, **backend,
                on_result=on_result, progress=not quiet)
        if campaign.sweep is not None:
            _sweep(campaign, store, work, workers, backend, quiet)
        # a stop while it writes leaves the run interrupted, not running
        store.finish(RunStatus.COMPLETE)
    except KeyboardInterrupt as stop:
        store.finish(RunStatus.INTERRUPTED)
        raise CampaignInterrupted(store, getattr(stop, "signum", signal.SIGINT)) from None
    return store
