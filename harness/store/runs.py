"""The result store: one folder per campaign run, written atomically as cases finish.

:class:`RunStore` is one run folder: it creates and opens runs, stores each finished case, takes
the writer lock for a resume and reads the rows and trajectories back; :func:`load_run` reads a
run's rows.  The parts it is made of have their own modules: the results root
(:mod:`~mbh._harness.store.location`), the manifest and the listing of runs
(:mod:`~mbh._harness.store.manifest`), rows as Parquet part files
(:mod:`~mbh._harness.store.rows`), trajectory files (:mod:`~mbh._harness.store.trajectory_files`),
atomic writes (:mod:`~mbh._harness.store.files`), the writer lock
(:mod:`~mbh._harness.store.writer_lock`), errors and damaged files
(:mod:`~mbh._harness.store.problems`) and the cache of identical cases
(:mod:`~mbh._harness.store.cache`).

Layout of a run folder ``<root>/<run_id>/`` (root:
:func:`~mbh._harness.store.location.results_root`)::

    manifest.json                 run id, start/end, status, git commit + dirty flag, package
                                  versions, machine, the campaign file, scenario content hashes,
                                  schema version, calibration figure
    cases/part-<n>.parquet        case rows (long-format tidy table, one row per case), one part
                                  file per :meth:`RunStore.add`, written to a dot-prefixed temp
                                  name and renamed into place (``os.replace``)
    sweeps/part-<n>.parquet       stability-sweep rows, the same way
    trajectories/<case>.npz       one trajectory per case (body states + how the run ended)
    cases.parquet, sweeps.parquet all rows in one file each (migrated, one per case), written
                                  by :meth:`RunStore.finish` for readers using
                                  ``pd.read_parquet`` directly
    .writer.lock                  the writer's lock (:meth:`RunStore.lock`): one process writes
                                  a run at a time; its pid and start time

Reading concatenates the parts in write order and keeps the first row of each ``case_id``, so a
case written twice (a resume racing a crash) counts once; dot-prefixed temp files left by a
killed writer are never read.  Read a run with :func:`load_run` (any time) or
``pd.read_parquet(<run>/cases.parquet)`` (once finished or interrupted), not the ``cases/``
folder as a dataset: a column that only some parts carry, or that is None in the first part,
does not fit the first part's schema there.  Column types are declared in
:mod:`mbh._harness.store.schema`; older schema versions are migrated on read.
:class:`~mbh._harness.store.cache.CaseCache` keeps rows and trajectories of identical cases
across runs under ``<root>/cache/`` for ``mbh run --reuse``.

Damaged files (docs/formats/store.md, "Damaged files"): reading never fails on a part file,
trajectory or manifest that was cut or overwritten.  What is intact is read; each damaged file is
named with its problem in :attr:`RunStore.problems` (and by :func:`load_run` as a
:class:`StoreWarning`); a run whose manifest cannot be read lists with status ``unreadable``.  The
run's next writer (``--resume``) renames damaged parts to ``<part>.damaged``, so their cases run
again.  A write that fails (a read-only or full disk) raises :class:`StoreError` naming the file
and the problem; :meth:`RunStore.check_writable` tries the results root before a run starts.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from mbh._harness.common.machine_speed import workload_name
from mbh._harness.model import scenario
from mbh._harness.common.status import FINISHED_RUN_STATUSES, RunStatus
from mbh._harness.model.trajectory import Trajectory
from mbh._harness.store.files import write_json, write_table
from mbh._harness.store.location import check_writable, root_or_default
from mbh._harness.store.manifest import (MANIFEST, list_runs, manifest_of, new_manifest,
                                         timestamp)
from mbh._harness.store.rerun import campaign_argument
from mbh._harness.store.problems import (DAMAGE, MissingTrajectory, StoreError, StoreProblem,
                                         StoreWarning, write_problem, writing)
from mbh._harness.store.rows import PartTable
from mbh._harness.store.schema import CASE_COLUMNS, SCHEMA_VERSION, SWEEP_COLUMNS, VERSION_KEY
from mbh._harness.store.trajectory_files import (load_trajectory, save_trajectory,
                                                 trajectory_name)
from mbh._harness.store.writer_lock import lock_run_folder

__all__ = ["RunStore", "load_run"]


class RunStore:
    """One run folder (see the module docstring).  Make one with :meth:`create` or :meth:`open`.

    Attributes
    ----------
    run_id : str
        ``<UTC yyyymmddThhmmssZ>-<campaign name>`` (``-2``, ``-3``... on a clash).
    path : Path
        The run folder.
    manifest : dict
        The manifest, migrated to the current schema.
    """

    def __init__(self, path: Path, manifest: dict):
        self.path = path
        self.run_id = manifest["run_id"]
        self.manifest = manifest
        version = manifest["created_schema_version"]
        self._problems: dict[StoreProblem, None] = {}
        self._cases = PartTable(path / "cases", CASE_COLUMNS, "case_id", version, self._damage)
        self._sweeps = PartTable(path / "sweeps", SWEEP_COLUMNS, "sweep_id", version,
                                 self._damage)
        self._writer_lock = None

    def _damage(self, path: Path, problem: str) -> None:
        self._problems[StoreProblem(str(path), problem)] = None

    @property
    def problems(self) -> list[StoreProblem]:
        """The damaged files met so far (manifest when opened; parts and trajectories as they
        are read), each with what was left out; empty for an intact run."""
        return list(self._problems)

    #: Fail early when the results root cannot take a run
    #: (:func:`mbh._harness.store.location.check_writable`).
    check_writable = staticmethod(check_writable)

    def lock(self) -> None:
        """Become the run's one writer until :meth:`finish` (or this process's end): check
        that the results root takes writes (:meth:`check_writable`), take the lock, and rename
        damaged part files to ``<part>.damaged`` (recorded in the manifest's ``set_aside``) so
        that their cases run again.

        Raises
        ------
        RunLocked
            When another live process is writing the run (the message names it).
        StoreError
            When the run's manifest cannot be read, or the root takes no writes.
        """
        if self._writer_lock is not None:
            return
        if self.manifest["status"] == RunStatus.UNREADABLE:
            raise StoreError(f"{self.problems[0]}; the run cannot be written to (start a new run)")
        check_writable(self.path.parent)
        self._writer_lock = lock_run_folder(self.path)
        self._set_aside_damaged()

    def _set_aside_damaged(self) -> None:
        damaged = self._cases.damaged() + self._sweeps.damaged()
        if not damaged:
            return
        with writing(self.path):
            for path in damaged:
                path.rename(path.with_name(path.name + ".damaged"))
        self.manifest.setdefault("set_aside", []).extend(
            {"file": str(problem.file), "problem": problem.problem, "at": timestamp()}
            for problem in self.problems if Path(problem.file) in damaged)
        self._problems = {p: None for p in self._problems if Path(p.file) not in damaged}
        self._write_manifest()

    @classmethod
    def create(cls, campaign, root: Path | None = None) -> "RunStore":
        """A new run folder for ``campaign`` (a :class:`mbh._harness.run.spec.Campaign`; reads its
        name, path, text, cases and sweep).

        Raises
        ------
        mbh._harness.model.scenario.ScenarioError
            When a scenario of the campaign does not load (the manifest records the content
            hash of each scenario its cases and sweep use).
        """
        root = check_writable(root)
        started = _dt.datetime.now(_dt.timezone.utc)
        base = f"{started:%Y%m%dT%H%M%SZ}-{campaign.name}"
        sweep = getattr(campaign, "sweep", None)
        scenarios = sorted({case.scenario for case in campaign.cases}
                           | set(sweep.scenarios if sweep else ()))
        hashes = {name: scenario.load(name).content_hash for name in scenarios}
        for attempt in range(1, 1000):
            run_id = base if attempt == 1 else f"{base}-{attempt}"
            try:
                (root / run_id).mkdir()
                break
            except FileExistsError:
                continue
            except OSError as error:
                raise StoreError(write_problem(root / run_id, error)) from None
        else:
            raise FileExistsError(f"{root}: no free run folder name for {base}")
        manifest = new_manifest(run_id, campaign, started, hashes)
        store = cls(root / run_id, manifest)
        store._write_manifest()
        return store

    @classmethod
    def open(cls, run_id: str, root: Path | None = None) -> "RunStore":
        """The existing run ``run_id`` under ``root``.

        A run whose manifest cannot be read opens for reading, with the stand-in manifest
        :func:`list_runs` shows (status ``unreadable``) and the problem in
        :attr:`problems`; :meth:`lock` refuses it.

        Raises
        ------
        FileNotFoundError
            When there is no such run (the message lists the runs there are).
        SchemaError
            When a newer mbh wrote the run.
        """
        root = root_or_default(root)
        path = root / run_id
        if not (path / MANIFEST).is_file():
            known = ", ".join(m["run_id"] for m in list_runs(root)) or "none"
            raise FileNotFoundError(f"no run {run_id!r} under {root} (runs: {known})")
        manifest, problem = manifest_of(path)
        store = cls(path, manifest)
        if problem is not None:
            store._problems[problem] = None
        return store

    def _write_manifest(self) -> None:
        with writing(self.path / MANIFEST):
            write_json(self.path / MANIFEST, self.manifest)

    def add(self, row: dict, trajectory: Trajectory | None) -> None:
        """Store one finished case: its trajectory file first, then its row (a part file).

        ``row`` is a flat dict of scalars with at least ``case_id``; the store adds ``run_id``
        and ``trajectory_file`` (path relative to the run folder, None without a trajectory).

        Raises
        ------
        TypeError
            When a row value is not a scalar or does not fit its column's declared type.
        StoreError
            When a file cannot be written (a full or read-only disk): the case is not stored,
            the run is marked ``interrupted`` if its manifest can still be written, the writer
            lock is released, and every case stored before stays intact for ``--resume``.
        """
        if not isinstance(row.get("case_id"), str):
            raise ValueError(f"a case row needs a str case_id, got {row.get('case_id')!r}")
        stored = {**row, "run_id": self.run_id, "trajectory_file": None}
        with self._stopping_on_failed_writes(f"case {row['case_id']!r}"):
            if trajectory is not None:
                name = Path("trajectories") / trajectory_name(row["case_id"])
                save_trajectory(self.path / name, trajectory)
                stored["trajectory_file"] = name.as_posix()
            self._cases.append(stored)

    def add_sweep(self, row: dict) -> None:
        """Store one stability-sweep row (a flat dict of scalars; ``sweep_id`` dedupes); a
        failed write stops the run as in :meth:`add`."""
        with self._stopping_on_failed_writes(f"sweep row {row.get('sweep_id')!r}"):
            self._sweeps.append({**row, "run_id": self.run_id})

    @contextlib.contextmanager
    def _stopping_on_failed_writes(self, what: str):
        try:
            with writing(self.path):
                yield
        except StoreError as error:
            try:
                self.manifest.update(status=RunStatus.INTERRUPTED, ended=timestamp())
                self._write_manifest()
                marked = "marked interrupted"
            except StoreError:
                marked = "left marked running (its manifest cannot be written either)"
            if self._writer_lock is not None:
                self._writer_lock.close()
                self._writer_lock = None
            stored = len(self._cases.keys())
            raise StoreError(f"{error}; {what} is not stored and the run stops: run "
                             f"{self.run_id} is {marked} and keeps its {stored} stored cases "
                             f"intact; make room, then resume it with: mbh run "
                             f"{campaign_argument(self.manifest)} --resume {self.run_id}") from None

    def done_case_ids(self) -> set[str]:
        """Case ids with a stored row (whatever their status): what ``--resume`` skips."""
        return self._cases.keys()

    def set_calibration(self, seconds: float, workload: str | None = None) -> None:
        """Record the run's machine-speed figure, s (positive and finite), and the workload that
        measured it (default: this process's,
        :func:`~mbh._harness.common.machine_speed.workload_name`)."""
        seconds = float(seconds)
        if not np.isfinite(seconds) or seconds <= 0:
            raise ValueError(f"calibration time must be positive and finite, got {seconds!r} s")
        self.manifest["calibration_s"] = seconds
        self.manifest["calibration_workload"] = workload or workload_name()
        self._write_manifest()

    @property
    def calibration_s(self) -> float | None:
        """The run's machine-speed figure, s (:mod:`mbh._harness.common.machine_speed`): None until
        :meth:`set_calibration`, and for a run stored before the figure was that workload's
        (its ``calibration_s`` timed an in-house case, which followed the in-house code's speed
        rather than the machine's)."""
        if self.calibration_workload is None:
            return None
        return self.manifest.get("calibration_s")

    @property
    def calibration_workload(self) -> str | None:
        """What measured :attr:`calibration_s`
        (:func:`~mbh._harness.common.machine_speed.workload_name`; two figures compare only when
        these are equal), or None."""
        return self.manifest.get("calibration_workload")

    def mark_running(self) -> None:
        """Set the status back to ``running`` (a resumed run), clearing the end time."""
        self.manifest.update(status=RunStatus.RUNNING, ended=None)
        self._write_manifest()

    def finish(self, status: RunStatus) -> None:
        """Record the end time and ``status`` (one of
        :data:`~mbh._harness.common.status.FINISHED_RUN_STATUSES`); write the one-file exports
        ``cases.parquet`` and ``sweeps.parquet``."""
        if status not in FINISHED_RUN_STATUSES:
            raise ValueError(f"run status must be one of {', '.join(FINISHED_RUN_STATUSES)}, "
                             f"got {status!r}")
        for part_table, name in ((self._cases, "cases.parquet"),
                                 (self._sweeps, "sweeps.parquet")):
            table = part_table.table()
            if table is not None:
                table = table.replace_schema_metadata({VERSION_KEY: str(SCHEMA_VERSION).encode()})
                with writing(self.path / name):
                    write_table(self.path / name, table)
        self.manifest.update(status=status, ended=timestamp())
        self._write_manifest()
        if self._writer_lock is not None:
            self._writer_lock.close()
            self._writer_lock = None

    def cases(self) -> pd.DataFrame:
        """All case rows, one per ``case_id``, in the order they were stored (the rows of
        damaged parts left out, and a row whose trajectory file is missing kept; both named in
        :attr:`problems`)."""
        frame = self._cases.frame()
        if "trajectory_file" not in frame.columns:  # a schema-1 run kept none
            return frame
        for case_id, name in zip(frame["case_id"], frame["trajectory_file"]):
            if isinstance(name, str) and not (self.path / name).is_file():
                self._damage(self.path / name, f"missing trajectory; case {case_id!r} keeps "
                                               f"its row but has no body states")
        return frame

    def sweeps(self) -> pd.DataFrame:
        """All stability-sweep rows, one per ``sweep_id``."""
        return self._sweeps.frame()

    def trajectory(self, case_id: str) -> Trajectory:
        """The stored trajectory of ``case_id``.

        Raises
        ------
        MissingTrajectory
            A KeyError: when the run holds no trajectory for that case, or its file is damaged
            (then also named in :attr:`problems`).
        """
        path = self.path / "trajectories" / trajectory_name(case_id)
        if not path.is_file():
            raise MissingTrajectory(f"run {self.run_id}: no trajectory stored for case "
                                    f"{case_id!r}")
        try:
            return load_trajectory(path)
        except DAMAGE as error:
            problem = f"damaged trajectory ({type(error).__name__}: {error})"
            self._damage(path, problem)
            raise MissingTrajectory(f"{path}: {problem}; case {case_id!r} has no body "
                                    f"states") from None



def load_run(run_id: str, root: Path | None = None) -> pd.DataFrame:
    """The case rows of run ``run_id``: ``RunStore.open(run_id, root).cases()``; each damaged
    file met (:attr:`RunStore.problems`) is named in a :class:`StoreWarning`."""
    store = RunStore.open(run_id, root)
    cases = store.cases()
    for problem in store.problems:
        warnings.warn(f"run {run_id}: {problem}", StoreWarning, stacklevel=2)
    return cases
