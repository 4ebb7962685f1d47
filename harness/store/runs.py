"""The result store: one folder per campaign run, written atomically as cases finish.

Layout of a run folder ``<root>/<run_id>/`` (root: :func:`results_root`)::

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
:mod:`mbh._harness.store.schema`; older schema versions are migrated on read.  :class:`CaseCache`
keeps rows and trajectories of identical cases across runs under ``<root>/cache/`` for
``mbh run --reuse``.

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
import errno
import fcntl
import hashlib
import json
import os
import re
import shutil
import threading
import warnings
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from mbh._harness.common.locations import checkout, user_data
from mbh._harness.common import jsonout
from mbh._harness.common.errors import MbhError
from mbh._harness.common.machine_speed import workload_name

from mbh._harness.model import scenario
from mbh._harness.common.environment import git_state, machine, package_versions
from mbh._harness.store.schema import (CASE_COLUMNS, SCHEMA_VERSION, SWEEP_COLUMNS, VERSION_KEY,
                                  SchemaError, column_type, migrate_manifest, migrate_table)
from mbh._harness.model.trajectory import Trajectory

__all__ = ["SCHEMA_VERSION", "results_root", "RunStore", "list_runs", "latest_run", "load_run",
           "case_frame", "CaseCache", "RUN_STATUSES", "UNREADABLE", "StoreError", "StoreProblem",
           "StoreWarning", "MissingTrajectory"]

#: Environment variable naming the results root.
ROOT_ENV = "MBH_RESULTS_DIR"

#: A run's ``status`` in its manifest.
RUN_STATUSES = ("running", "complete", "interrupted")

#: The status :func:`list_runs` gives a run whose manifest cannot be read.
UNREADABLE = "unreadable"

#: Least free space on the results root's disk for a run to start, bytes: room for the manifest,
#: the first parts and trajectories (a case stores a ~10 kB part and a trajectory of at most
#: ~0.5 MB, the 4 s of the largest shipped scene), so a nearly full disk fails before any case.
MIN_FREE_BYTES = 16 * 2**20
#: Size of the probe file :meth:`RunStore.check_writable` writes, bytes.
_PROBE_BYTES = 64 * 2**10

#: Statuses the cache never keeps: they describe the machine's load, not the case.
UNCACHED_STATUSES = ("timeout", "crashed")

_MANIFEST = "manifest.json"
_PART = re.compile(r"^part-(\d+)\.parquet$")
_TRAJECTORY_ARRAYS = ("times", "position", "quaternion", "velocity", "angular_velocity")
# Nullable pandas dtypes for integer and boolean columns, so a None keeps them integer/boolean.
_PANDAS_TYPES = {pa.int64(): pd.Int64Dtype(), pa.bool_(): pd.BooleanDtype()}.get


def results_root() -> Path:
    """The results root: ``$MBH_RESULTS_DIR`` if set, else ``results`` in the checkout the harness
    runs from, else ``results`` in the user data folder (an installed harness never writes into
    its own package)."""
    configured = os.environ.get(ROOT_ENV)
    if configured:
        return Path(configured)
    repository = checkout()
    return (repository if repository is not None else user_data()) / "results"


def _now() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="microseconds")


# --- errors ---------------------------------------------------------------------------------

class StoreError(MbhError, ValueError):
    """A results root, run folder or stored file that cannot be read or written as asked; the
    message names the file and the problem."""


class MissingTrajectory(MbhError, KeyError):
    """A case without a readable stored trajectory (none stored, or its file is damaged)."""

    def __str__(self) -> str:
        return str(self.args[0])


class StoreWarning(UserWarning):
    """Rows or files of a stored run left out because a file is damaged."""


@dataclass(frozen=True)
class StoreProblem:
    """A damaged file of a run and what reading left out because of it."""

    file: str
    problem: str

    def __str__(self) -> str:
        return f"{self.file}: {self.problem}"


#: What reading a damaged file raises: pyarrow's ArrowInvalid (a ValueError) for a cut or
#: overwritten Parquet file, BadZipFile or ValueError for an npz, JSONDecodeError, KeyError for a
#: missing column or array, TypeError for fields of the wrong kind, OSError for an unreadable file.
_DAMAGE = (OSError, ValueError, KeyError, TypeError, EOFError, zipfile.BadZipFile)


def _write_problem(path: Path, error: OSError) -> str:
    """``PATH: cannot write: REASON (what it means)`` for a failed write."""
    where = error.filename or path
    meaning = {errno.ENOSPC: "the disk is full", errno.EDQUOT: "the disk quota is used up",
               errno.EROFS: "the file system is read-only",
               errno.EACCES: "no permission to write there",
               errno.EPERM: "no permission to write there"}.get(error.errno)
    return f"{where}: cannot write: {error.strerror or error}" + (f" ({meaning})" if meaning
                                                                   else "")


@contextlib.contextmanager
def _writing(path: Path):
    """Within the block, an OSError becomes a :class:`StoreError` naming the file."""
    try:
        yield
    except OSError as error:
        raise StoreError(_write_problem(path, error)) from None


# --- atomic files ---------------------------------------------------------------------------

def _atomic_write(path: Path, write) -> None:
    """Call ``write(file)`` on a dot-prefixed temp file beside ``path``, then rename it."""
    temp = path.with_name(f".{path.name}.tmp-{os.getpid()}-{threading.get_ident()}")
    try:
        with open(temp, "wb") as file:
            write(file)
            file.flush()
            os.fsync(file.fileno())
        os.replace(temp, path)
    finally:
        temp.unlink(missing_ok=True)


def _write_json(path: Path, document: dict) -> None:
    _atomic_write(path, lambda file: file.write(jsonout.dumps(document).encode()))


#: Keys every manifest has, each a string (what listing and opening a run read first).
_MANIFEST_KEYS = ("run_id", "campaign", "started", "status")


def _read_manifest(path: Path) -> dict:
    """The manifest in ``path``, migrated.

    Raises
    ------
    StoreError
        When the file is cut, overwritten or not a manifest (the message names it and why).
    SchemaError
        When a newer mbh wrote it.
    """
    try:
        manifest = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as error:  # JSONDecodeError, UnicodeDecodeError
        raise StoreError(f"{path}: unreadable manifest ({type(error).__name__}: {error}); the "
                         f"file was cut or overwritten") from None
    missing = [key for key in _MANIFEST_KEYS
               if not isinstance(manifest, dict) or not isinstance(manifest.get(key), str)]
    if missing:
        raise StoreError(f"{path}: not a run manifest (no {', '.join(missing)})")
    return migrate_manifest(manifest, str(path))


def _unreadable_manifest(folder: Path, problem: StoreProblem) -> dict:
    """What stands for a manifest that cannot be read: the folder's name as the run id, status
    :data:`UNREADABLE`, the problem under ``problems``; parts are read at their own version."""
    return {"run_id": folder.name, "campaign": "", "started": "", "ended": None,
            "status": UNREADABLE, "n_cases": None, "schema_version": SCHEMA_VERSION,
            "created_schema_version": SCHEMA_VERSION, "calibration_s": None,
            "problems": [str(problem)]}


def _manifest_of(folder: Path, tolerated=(StoreError,)) -> tuple[dict, StoreProblem | None]:
    """The folder's manifest and None, or (for an error of ``tolerated``) the stand-in and the
    problem."""
    path = folder / _MANIFEST
    try:
        return _read_manifest(path), None
    except tolerated as error:
        problem = StoreProblem(str(path), str(error).removeprefix(f"{path}: "))
        return _unreadable_manifest(folder, problem), problem


# --- rows as Parquet ------------------------------------------------------------------------

def _scalar(value):
    return value.item() if isinstance(value, np.generic) else value


def _row_table(row: dict, columns: dict[str, pa.DataType]) -> pa.Table:
    """One-row table of ``row`` with declared column types, tagged with the schema version.

    Raises
    ------
    TypeError
        Naming the column whose value is not a scalar or does not fit its declared type.
    """
    arrays, fields = [], []
    for name, value in row.items():
        value = _scalar(value)
        kind = column_type(columns, name, value)
        try:
            arrays.append(pa.array([value], type=kind))
        except (pa.ArrowInvalid, pa.ArrowTypeError, TypeError) as error:
            raise TypeError(f"row column {name!r}: {value!r} is not a {kind}: {error}") from None
        fields.append(pa.field(name, kind))
    schema = pa.schema(fields, metadata={VERSION_KEY: str(SCHEMA_VERSION).encode()})
    return pa.Table.from_arrays(arrays, schema=schema)


def _write_table(path: Path, table: pa.Table) -> None:
    _atomic_write(path, lambda file: pq.write_table(table, file))


def _read_table(path: Path, fallback_version: int) -> pa.Table:
    """The table in ``path`` migrated to the current schema."""
    table = pq.read_table(path)
    metadata = table.schema.metadata or {}
    version = int(metadata[VERSION_KEY]) if VERSION_KEY in metadata else fallback_version
    return migrate_table(table.replace_schema_metadata(None), version, str(path))


def _to_frame(table: pa.Table | None, columns: dict[str, pa.DataType]) -> pd.DataFrame:
    if table is None:
        table = pa.schema(list(columns.items())).empty_table()
    return table.to_pandas(types_mapper=_PANDAS_TYPES)


def case_frame(row: dict) -> pd.DataFrame:
    """One case row as a one-row DataFrame with the column types :func:`load_run` gives.

    Raises
    ------
    TypeError
        Naming the column whose value does not fit its declared type.
    """
    return _to_frame(_row_table(row, CASE_COLUMNS), CASE_COLUMNS)


class _PartTable:
    """A table kept as numbered Parquet part files in one folder (one file per append).

    Parameters
    ----------
    folder : Path
        Where the parts live.
    columns : dict
        Declared column types (:mod:`mbh._harness.store.schema`).
    key : str
        Column identifying a row; reading keeps the first row of each key (when present).
    fallback_version : int
        Schema version of parts whose metadata does not say.
    on_problem : callable
        ``on_problem(path, problem)``, called for each damaged part (which reading skips).
    """

    def __init__(self, folder: Path, columns: dict[str, pa.DataType], key: str,
                 fallback_version: int, on_problem):
        self.folder, self.columns, self.key = folder, columns, key
        self.fallback_version = fallback_version
        self.on_problem = on_problem
        self._lock = threading.Lock()
        self._types: dict[str, pa.DataType] | None = None  # undeclared columns seen so far

    def _check_types(self, table: pa.Table) -> None:
        """Refuse an undeclared column whose type differs from the one earlier parts hold.

        Integer and float mix (read as float), None fits any type; anything else would make
        the parts impossible to concatenate, so it is refused here, at write time.

        Raises
        ------
        TypeError
            Naming the column, its new type and the type already stored.
        """
        if self._types is None:
            self._types = {}
            for path in self.parts():
                schema = self._readable(path, pq.read_schema)
                if schema is not None:
                    self._record(schema)
        for field in table.schema:
            known = self._types.get(field.name)
            if field.name in self.columns or pa.types.is_null(field.type) or known is None:
                continue
            numeric = {known, field.type} <= {pa.int64(), pa.float64()}
            if known != field.type and not numeric:
                raise TypeError(f"row column {field.name!r}: a {field.type} value, but earlier "
                                f"rows of this run hold {known} there")
        self._record(table.schema)

    def _record(self, schema: pa.Schema) -> None:
        for field in schema:
            if field.name in self.columns or pa.types.is_null(field.type):
                continue
            if self._types.get(field.name) != pa.float64():
                self._types[field.name] = field.type

    def parts(self) -> list[Path]:
        """Finished part files in write order (temp files excluded)."""
        if not self.folder.is_dir():
            return []
        numbered = [(int(m.group(1)), p) for p in self.folder.iterdir()
                    if (m := _PART.match(p.name))]
        return [path for _, path in sorted(numbered)]

    def append(self, row: dict) -> None:
        table = _row_table(row, self.columns)
        with self._lock:
            self._check_types(table)
            self.folder.mkdir(parents=True, exist_ok=True)
            parts = self.parts()
            number = int(_PART.match(parts[-1].name).group(1)) + 1 if parts else 0
            _write_table(self.folder / f"part-{number:06d}.parquet", table)

    def _readable(self, path: Path, read):
        """``read(path)``, or None for a damaged part (reported, with its rows left out)."""
        try:
            return read(path)
        except SchemaError:  # a newer mbh wrote it: not damage, and not to be skipped
            raise
        except _DAMAGE as error:
            self.on_problem(path, f"damaged part file ({type(error).__name__}: {error}); its "
                                  f"rows are left out")
            return None

    def damaged(self) -> list[Path]:
        """Part files that cannot be read as tables."""
        return [path for path in self.parts()
                if self._readable(path, lambda p: _read_table(p, self.fallback_version)) is None]

    def keys(self) -> set[str]:
        keys = set()
        for path in self.parts():
            column = self._readable(path, lambda p: pq.read_table(p, columns=[self.key])
                                    if self.key in pq.read_schema(p).names else None)
            if column is not None:
                keys.update(column.column(0).to_pylist())
        return keys

    def _concatenated(self, tables: list[tuple[Path, pa.Table]]) -> pa.Table:
        """The tables as one; a part whose columns fit none of the others' types is reported
        and left out."""
        try:
            return pa.concat_tables([t for _, t in tables], promote_options="permissive")
        except (pa.ArrowInvalid, pa.ArrowTypeError):
            pass
        table = tables[0][1]
        for path, part in tables[1:]:
            try:
                table = pa.concat_tables([table, part], promote_options="permissive")
            except (pa.ArrowInvalid, pa.ArrowTypeError) as error:
                self.on_problem(path, f"damaged part file (its columns do not fit the other "
                                      f"parts': {error}); its rows are left out")
        return table

    def table(self) -> pa.Table | None:
        """All rows, migrated, first row per key; None when there is no readable part."""
        tables = [(path, table) for path in self.parts()
                  if (table := self._readable(path, lambda p: _read_table(
                      p, self.fallback_version))) is not None]
        if not tables:
            return None
        table = self._concatenated(tables)
        if self.key not in table.column_names:
            return table
        keys = table.column(self.key).to_pylist()
        seen, first = set(), []
        for index, key in enumerate(keys):
            if key not in seen:
                seen.add(key)
                first.append(index)
        return table.take(first)

    def frame(self) -> pd.DataFrame:
        return _to_frame(self.table(), self.columns)


# --- trajectories ---------------------------------------------------------------------------

def _json_default(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"cannot store a {type(value).__name__} in a trajectory: {value!r}")


def _save_trajectory(path: Path, trajectory: Trajectory) -> None:
    """``trajectory`` as an npz: its arrays plus a JSON string of everything else."""
    meta = {"status": trajectory.status, "reason": trajectory.reason,
            "failure_time": trajectory.failure_time, "wall_time_s": trajectory.wall_time_s,
            "steps": trajectory.steps, "counters": trajectory.counters,
            "notes": trajectory.notes}
    arrays = {name: np.asarray(getattr(trajectory, name), dtype=float)
              for name in _TRAJECTORY_ARRAYS}
    arrays["meta"] = np.array(json.dumps(meta, default=_json_default))
    path.parent.mkdir(parents=True, exist_ok=True)
    _atomic_write(path, lambda file: np.savez(file, **arrays))


def _load_trajectory(path: Path) -> Trajectory:
    with np.load(path, allow_pickle=False) as data:
        arrays = {name: data[name] for name in _TRAJECTORY_ARRAYS}
        meta = json.loads(str(data["meta"]))
    return Trajectory(**arrays, **meta)


def _trajectory_name(case_id: str) -> str:
    """A file name for ``case_id``: readable part plus a hash (unique, filesystem-safe)."""
    readable = re.sub(r"[^A-Za-z0-9._=-]+", "_", case_id)[:100]
    return f"{readable}-{hashlib.sha256(case_id.encode()).hexdigest()[:12]}.npz"


# --- runs -----------------------------------------------------------------------------------

def _root(root) -> Path:
    return Path(root) if root is not None else results_root()


def _run_folders(root: Path) -> list[Path]:
    if not root.is_dir():
        return []
    return [path for path in root.iterdir() if (path / _MANIFEST).is_file()]


#: A run folder's writer lock: a file locked with ``flock``, which the kernel releases when its
#: process ends (however it ends), so a dead writer's lock is taken over by the next one.
_WRITER_LOCK = ".writer.lock"


class RunLocked(MbhError, RuntimeError):
    """Another live process is writing the run; the message names its pid and start time."""


def _lock_run_folder(path: Path):
    """Take ``path``'s writer lock without waiting and record who holds it; the returned open
    file holds the lock until it is closed or the process ends.  Raises :class:`RunLocked`."""
    handle = open(path / _WRITER_LOCK, "a+", encoding="utf-8")
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        handle.seek(0)
        holder = handle.read().strip() or "a process that has not said who it is"
        handle.close()
        raise RunLocked(f"{path}: the run is being written by {holder}; one process writes a "
                        f"run at a time (stop that one, e.g. with Ctrl-C, then --resume)") from None
    handle.seek(0)
    handle.truncate()
    handle.write(f"process {os.getpid()}, started {_now()}")
    handle.flush()
    return handle


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
        self._cases = _PartTable(path / "cases", CASE_COLUMNS, "case_id", version, self._damage)
        self._sweeps = _PartTable(path / "sweeps", SWEEP_COLUMNS, "sweep_id", version,
                                  self._damage)
        self._writer_lock = None

    def _damage(self, path: Path, problem: str) -> None:
        self._problems[StoreProblem(str(path), problem)] = None

    @property
    def problems(self) -> list[StoreProblem]:
        """The damaged files met so far (manifest when opened; parts and trajectories as they
        are read), each with what was left out; empty for an intact run."""
        return list(self._problems)

    @staticmethod
    def check_writable(root: Path | None = None) -> Path:
        """Fail early when the results root cannot take a run: create it if needed, write,
        sync and remove a probe file in it, and require :data:`MIN_FREE_BYTES` free on its disk.

        Returns
        -------
        Path
            The root.

        Raises
        ------
        StoreError
            Naming the root and the problem (not a folder, read-only, full).
        """
        root = _root(root)
        if root.exists() and not root.is_dir():
            raise StoreError(f"results root {root}: not a folder")
        probe = root / f".write-probe-{os.getpid()}-{threading.get_ident()}"
        try:
            root.mkdir(parents=True, exist_ok=True)
            _atomic_write(probe, lambda file: file.write(bytes(_PROBE_BYTES)))
            probe.unlink()
            free = shutil.disk_usage(root).free
        except OSError as error:
            raise StoreError(f"results root {root}: " + _write_problem(root, error)) from None
        if free < MIN_FREE_BYTES:
            raise StoreError(f"results root {root}: only {free / 2**20:.1f} MiB free on its "
                             f"disk; a run needs at least {MIN_FREE_BYTES / 2**20:g} MiB "
                             f"(the disk is full)")
        return root

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
        if self.manifest["status"] == UNREADABLE:
            raise StoreError(f"{self.problems[0]}; the run cannot be written to (start a new run)")
        self.check_writable(self.path.parent)
        self._writer_lock = _lock_run_folder(self.path)
        self._set_aside_damaged()

    def _set_aside_damaged(self) -> None:
        damaged = self._cases.damaged() + self._sweeps.damaged()
        if not damaged:
            return
        with _writing(self.path):
            for path in damaged:
                path.rename(path.with_name(path.name + ".damaged"))
        self.manifest.setdefault("set_aside", []).extend(
            {"file": str(problem.file), "problem": problem.problem, "at": _now()}
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
        root = RunStore.check_writable(root)
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
                raise StoreError(_write_problem(root / run_id, error)) from None
        else:
            raise FileExistsError(f"{root}: no free run folder name for {base}")
        manifest = {
            "schema_version": SCHEMA_VERSION, "created_schema_version": SCHEMA_VERSION,
            "run_id": run_id, "campaign": campaign.name, "campaign_path": str(campaign.path),
            "campaign_text": campaign.text, "n_cases": len(campaign.cases),
            "started": started.isoformat(timespec="microseconds"), "ended": None,
            "status": "running", "git": git_state(), "packages": package_versions(),
            "machine": machine(), "scenario_hashes": hashes, "calibration_s": None,
        }
        store = cls(root / run_id, manifest)
        store._write_manifest()
        return store

    @classmethod
    def open(cls, run_id: str, root: Path | None = None) -> "RunStore":
        """The existing run ``run_id`` under ``root``.

        A run whose manifest cannot be read opens for reading, with the stand-in manifest
        :func:`list_runs` shows (status :data:`UNREADABLE`) and the problem in
        :attr:`problems`; :meth:`lock` refuses it.

        Raises
        ------
        FileNotFoundError
            When there is no such run (the message lists the runs there are).
        SchemaError
            When a newer mbh wrote the run.
        """
        root = _root(root)
        path = root / run_id
        if not (path / _MANIFEST).is_file():
            known = ", ".join(m["run_id"] for m in list_runs(root)) or "none"
            raise FileNotFoundError(f"no run {run_id!r} under {root} (runs: {known})")
        manifest, problem = _manifest_of(path)
        store = cls(path, manifest)
        if problem is not None:
            store._problems[problem] = None
        return store

    def _write_manifest(self) -> None:
        with _writing(self.path / _MANIFEST):
            _write_json(self.path / _MANIFEST, self.manifest)

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
                name = Path("trajectories") / _trajectory_name(row["case_id"])
                _save_trajectory(self.path / name, trajectory)
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
            with _writing(self.path):
                yield
        except StoreError as error:
            try:
                self.manifest.update(status="interrupted", ended=_now())
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
                             f"{self.manifest.get('campaign')} --resume {self.run_id}") from None

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
        """What measured :attr:`calibration_s` (:func:`~mbh._harness.common.machine_speed.workload_name`;
        two figures compare only when these are equal), or None."""
        return self.manifest.get("calibration_workload")

    def mark_running(self) -> None:
        """Set the status back to ``running`` (a resumed run), clearing the end time."""
        self.manifest.update(status="running", ended=None)
        self._write_manifest()

    def finish(self, status: str) -> None:
        """Record the end time and ``status`` ("complete" or "interrupted"); write the
        one-file exports ``cases.parquet`` and ``sweeps.parquet``."""
        if status not in RUN_STATUSES[1:]:
            raise ValueError(f"run status must be one of {RUN_STATUSES[1:]}, got {status!r}")
        for part_table, name in ((self._cases, "cases.parquet"),
                                 (self._sweeps, "sweeps.parquet")):
            table = part_table.table()
            if table is not None:
                table = table.replace_schema_metadata({VERSION_KEY: str(SCHEMA_VERSION).encode()})
                with _writing(self.path / name):
                    _write_table(self.path / name, table)
        self.manifest.update(status=status, ended=_now())
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
        path = self.path / "trajectories" / _trajectory_name(case_id)
        if not path.is_file():
            raise MissingTrajectory(f"run {self.run_id}: no trajectory stored for case "
                                    f"{case_id!r}")
        try:
            return _load_trajectory(path)
        except _DAMAGE as error:
            problem = f"damaged trajectory ({type(error).__name__}: {error})"
            self._damage(path, problem)
            raise MissingTrajectory(f"{path}: {problem}; case {case_id!r} has no body "
                                    f"states") from None


def list_runs(root: Path | None = None) -> list[dict]:
    """Manifests of every run under ``root`` (migrated), oldest start first; a run whose
    manifest cannot be read comes first, as a stand-in with status :data:`UNREADABLE` and the
    problem under ``problems``."""
    manifests = [_manifest_of(path, (StoreError, SchemaError))[0]
                 for path in _run_folders(_root(root))]
    return sorted(manifests, key=lambda m: (m["started"], m["run_id"]))


def latest_run(campaign: str, root: Path | None = None, *, before: str | None = None,
               statuses: tuple[str, ...] = RUN_STATUSES[1:]) -> str | None:
    """The id of the latest stored run of campaign ``campaign`` whose status is one of
    ``statuses`` (default: finished, complete or interrupted), or None when there is none.

    With ``before``, only runs started before run ``before`` count (None when ``before`` is not
    stored): the run a report of ``before`` compares with.  Without, every stored run counts:
    the run a new run of the campaign compares with.
    """
    manifests = list_runs(root)
    if before is not None:
        mine = next((m for m in manifests if m["run_id"] == before), None)
        if mine is None:
            return None
        manifests = [m for m in manifests if m["started"] < mine["started"]]
    runs = [m for m in manifests if m["campaign"] == campaign and m["status"] in statuses]
    return runs[-1]["run_id"] if runs else None


def load_run(run_id: str, root: Path | None = None) -> pd.DataFrame:
    """The case rows of run ``run_id``: ``RunStore.open(run_id, root).cases()``; each damaged
    file met (:attr:`RunStore.problems`) is named in a :class:`StoreWarning`."""
    store = RunStore.open(run_id, root)
    cases = store.cases()
    for problem in store.problems:
        warnings.warn(f"run {run_id}: {problem}", StoreWarning, stacklevel=2)
    return cases


# --- cache ----------------------------------------------------------------------------------

class CaseCache:
    """Rows and trajectories of finished cases, reusable by any run (``mbh run --reuse``).

    An entry is keyed by (scenario content hash, adapter name, adapter version, method string,
    dt, t_end, settings) and lives in ``<root>/cache/<key hash>/`` (row.parquet + trajectory.npz),
    written in a temp folder and renamed into place.  Rows with a status of
    :data:`UNCACHED_STATUSES` are not kept.

    Parameters
    ----------
    root : Path, optional
        Results root (default :func:`results_root`).
    """

    def __init__(self, root: Path | None = None):
        self.folder = _root(root) / "cache"

    @staticmethod
    def key(spec, scenario_hash: str, adapter_version: str, settings: str) -> str:
        """The entry name of ``spec`` (a CaseSpec: scenario, adapter, method, dt, t_end);
        ``settings`` is everything else the row depends on (the runner's: the code fingerprint,
        the verdict's bounds and the campaign's accuracy)."""
        parts = [scenario_hash, spec.adapter, str(adapter_version), spec.method,
                 repr(float(spec.dt)), repr(float(spec.t_end)), settings]
        return hashlib.sha256(json.dumps(parts).encode()).hexdigest()

    def lookup(self, spec, scenario_hash: str, adapter_version: str,
               settings: str) -> tuple[dict, Trajectory | None] | None:
        """The row and trajectory stored for an identical case, or None.

        The row comes back as it was put, with ``reused_from`` set to the run that computed it
        (``"cache"`` when unknown) and without the store's ``run_id``/``trajectory_file``.
        """
        entry = self.folder / self.key(spec, scenario_hash, adapter_version, settings)
        if not (entry / "row.parquet").is_file():
            return None
        trajectory_path = entry / "trajectory.npz"
        try:
            row = _read_table(entry / "row.parquet", SCHEMA_VERSION).to_pylist()[0]
            trajectory = _load_trajectory(trajectory_path) if trajectory_path.is_file() else None
        except _DAMAGE:  # a damaged entry is a miss: the case runs again
            return None
        row["reused_from"] = row.pop("run_id", None) or "cache"
        row.pop("trajectory_file", None)
        return row, trajectory

    def put(self, spec, scenario_hash: str, adapter_version: str, settings: str, row: dict,
            trajectory: Trajectory | None, run_id: str | None = None) -> None:
        """Keep ``row`` and ``trajectory`` for ``spec`` (first writer wins; see the class).

        Raises
        ------
        StoreError
            When the entry cannot be written (a full or read-only disk), naming the file.
        """
        if row.get("status") in UNCACHED_STATUSES:
            return
        name = self.key(spec, scenario_hash, adapter_version, settings)
        entry = self.folder / name
        if entry.is_dir():
            return
        temp = self.folder / f".{name}.tmp-{os.getpid()}-{threading.get_ident()}"
        with _writing(temp), contextlib.ExitStack() as cleanup:
            self.folder.mkdir(parents=True, exist_ok=True)
            temp.mkdir()
            cleanup.callback(shutil.rmtree, temp, ignore_errors=True)
            self._write_entry(temp, entry, row, trajectory, run_id)

    @staticmethod
    def _write_entry(temp: Path, entry: Path, row: dict, trajectory: Trajectory | None,
                     run_id: str | None) -> None:
        """Write the entry's files into ``temp`` and rename it to ``entry`` (a concurrent
        writer's entry, if one landed first, is kept)."""
        stored = {key: value for key, value in row.items()
                  if key not in ("run_id", "trajectory_file", "reused_from")}
        _write_table(temp / "row.parquet", _row_table({**stored, "run_id": run_id}, CASE_COLUMNS))
        if trajectory is not None:
            _save_trajectory(temp / "trajectory.npz", trajectory)
        try:
            os.rename(temp, entry)
        except OSError:
            if not entry.is_dir():
                raise
