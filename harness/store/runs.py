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
:mod:`harness.store.schema`; older schema versions are migrated on read.  :class:`CaseCache`
keeps rows and trajectories of identical cases across runs under ``<root>/cache/`` for
``mbh run --reuse``.
"""

from __future__ import annotations

import datetime as _dt
import fcntl
import hashlib
import json
import os
import re
import shutil
import threading
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from harness.common.locations import checkout, user_data
from harness.common import jsonout
from harness.common.errors import MbhError

from harness.model import scenario
from harness.common.environment import git_state, machine, package_versions
from harness.store.schema import (CASE_COLUMNS, SCHEMA_VERSION, SWEEP_COLUMNS, VERSION_KEY,
                                  column_type, migrate_manifest, migrate_table)
from harness.model.trajectory import Trajectory

__all__ = ["SCHEMA_VERSION", "results_root", "RunStore", "list_runs", "latest_run", "load_run",
           "case_frame",
           "CaseCache", "RUN_STATUSES"]

#: Environment variable naming the results root.
ROOT_ENV = "MBH_RESULTS_DIR"

#: A run's ``status`` in its manifest.
RUN_STATUSES = ("running", "complete", "interrupted")

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


def _read_json(path: Path) -> dict:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as error:
        raise ValueError(f"{path}: not valid JSON: {error}") from None


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
        Declared column types (:mod:`harness.store.schema`).
    key : str
        Column identifying a row; reading keeps the first row of each key (when present).
    fallback_version : int
        Schema version of parts whose metadata does not say.
    """

    def __init__(self, folder: Path, columns: dict[str, pa.DataType], key: str,
                 fallback_version: int):
        self.folder, self.columns, self.key = folder, columns, key
        self.fallback_version = fallback_version
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
                self._record(pq.read_schema(path))
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

    def keys(self) -> set[str]:
        keys = set()
        for path in self.parts():
            if self.key in pq.read_schema(path).names:
                keys.update(pq.read_table(path, columns=[self.key]).column(0).to_pylist())
        return keys

    def table(self) -> pa.Table | None:
        """All rows, migrated, first row per key; None when there is no part."""
        tables = [_read_table(path, self.fallback_version) for path in self.parts()]
        if not tables:
            return None
        table = pa.concat_tables(tables, promote_options="permissive")
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
        self._cases = _PartTable(path / "cases", CASE_COLUMNS, "case_id", version)
        self._sweeps = _PartTable(path / "sweeps", SWEEP_COLUMNS, "sweep_id", version)
        self._writer_lock = None

    def lock(self) -> None:
        """Become the run's one writer until :meth:`finish` (or this process's end).

        Raises
        ------
        RunLocked
            When another live process is writing the run (the message names it).
        """
        if self._writer_lock is None:
            self._writer_lock = _lock_run_folder(self.path)

    @classmethod
    def create(cls, campaign, root: Path | None = None) -> "RunStore":
        """A new run folder for ``campaign`` (a :class:`harness.run.spec.Campaign`; reads its
        name, path, text, cases and sweep).

        Raises
        ------
        harness.model.scenario.ScenarioError
            When a scenario of the campaign does not load (the manifest records the content
            hash of each scenario its cases and sweep use).
        """
        root = _root(root)
        root.mkdir(parents=True, exist_ok=True)
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

        Raises
        ------
        FileNotFoundError
            When there is no such run (the message lists the runs there are).
        """
        root = _root(root)
        path = root / run_id
        manifest_path = path / _MANIFEST
        if not manifest_path.is_file():
            known = ", ".join(m["run_id"] for m in list_runs(root)) or "none"
            raise FileNotFoundError(f"no run {run_id!r} under {root} (runs: {known})")
        return cls(path, migrate_manifest(_read_json(manifest_path), str(manifest_path)))

    def _write_manifest(self) -> None:
        _write_json(self.path / _MANIFEST, self.manifest)

    def add(self, row: dict, trajectory: Trajectory | None) -> None:
        """Store one finished case: its trajectory file first, then its row (a part file).

        ``row`` is a flat dict of scalars with at least ``case_id``; the store adds ``run_id``
        and ``trajectory_file`` (path relative to the run folder, None without a trajectory).

        Raises
        ------
        TypeError
            When a row value is not a scalar or does not fit its column's declared type.
        """
        if not isinstance(row.get("case_id"), str):
            raise ValueError(f"a case row needs a str case_id, got {row.get('case_id')!r}")
        stored = {**row, "run_id": self.run_id, "trajectory_file": None}
        if trajectory is not None:
            name = Path("trajectories") / _trajectory_name(row["case_id"])
            _save_trajectory(self.path / name, trajectory)
            stored["trajectory_file"] = name.as_posix()
        self._cases.append(stored)

    def add_sweep(self, row: dict) -> None:
        """Store one stability-sweep row (a flat dict of scalars; ``sweep_id`` dedupes)."""
        self._sweeps.append({**row, "run_id": self.run_id})

    def done_case_ids(self) -> set[str]:
        """Case ids with a stored row (whatever their status): what ``--resume`` skips."""
        return self._cases.keys()

    def set_calibration(self, seconds: float) -> None:
        """Record the calibration case's wall time, s (positive and finite)."""
        seconds = float(seconds)
        if not np.isfinite(seconds) or seconds <= 0:
            raise ValueError(f"calibration time must be positive and finite, got {seconds!r} s")
        self.manifest["calibration_s"] = seconds
        self._write_manifest()

    @property
    def calibration_s(self) -> float | None:
        """The calibration case's wall time, s (None until :meth:`set_calibration`)."""
        return self.manifest.get("calibration_s")

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
                _write_table(self.path / name, table)
        self.manifest.update(status=status, ended=_now())
        self._write_manifest()
        if self._writer_lock is not None:
            self._writer_lock.close()
            self._writer_lock = None

    def cases(self) -> pd.DataFrame:
        """All case rows, one per ``case_id``, in the order they were stored."""
        return self._cases.frame()

    def sweeps(self) -> pd.DataFrame:
        """All stability-sweep rows, one per ``sweep_id``."""
        return self._sweeps.frame()

    def trajectory(self, case_id: str) -> Trajectory:
        """The stored trajectory of ``case_id``.

        Raises
        ------
        KeyError
            When the run holds no trajectory for that case.
        """
        path = self.path / "trajectories" / _trajectory_name(case_id)
        if not path.is_file():
            raise KeyError(f"run {self.run_id}: no trajectory stored for case {case_id!r}")
        return _load_trajectory(path)


def list_runs(root: Path | None = None) -> list[dict]:
    """Manifests of every run under ``root`` (migrated), oldest start first."""
    manifests = [migrate_manifest(_read_json(path / _MANIFEST), str(path / _MANIFEST))
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
    """The case rows of run ``run_id``: ``RunStore.open(run_id, root).cases()``."""
    return RunStore.open(run_id, root).cases()


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
        row = _read_table(entry / "row.parquet", SCHEMA_VERSION).to_pylist()[0]
        trajectory_path = entry / "trajectory.npz"
        trajectory = _load_trajectory(trajectory_path) if trajectory_path.is_file() else None
        row["reused_from"] = row.pop("run_id", None) or "cache"
        row.pop("trajectory_file", None)
        return row, trajectory

    def put(self, spec, scenario_hash: str, adapter_version: str, settings: str, row: dict,
            trajectory: Trajectory | None, run_id: str | None = None) -> None:
        """Keep ``row`` and ``trajectory`` for ``spec`` (first writer wins; see the class)."""
        if row.get("status") in UNCACHED_STATUSES:
            return
        name = self.key(spec, scenario_hash, adapter_version, settings)
        entry = self.folder / name
        if entry.is_dir():
            return
        self.folder.mkdir(parents=True, exist_ok=True)
        temp = self.folder / f".{name}.tmp-{os.getpid()}-{threading.get_ident()}"
        temp.mkdir()
        try:
            stored = {key: value for key, value in row.items()
                      if key not in ("run_id", "trajectory_file", "reused_from")}
            _write_table(temp / "row.parquet",
                         _row_table({**stored, "run_id": run_id}, CASE_COLUMNS))
            if trajectory is not None:
                _save_trajectory(temp / "trajectory.npz", trajectory)
            try:
                os.rename(temp, entry)
            except OSError:
                if not entry.is_dir():
                    raise
        finally:
            shutil.rmtree(temp, ignore_errors=True)
