"""Finished cases kept for any later run (``mbh run --reuse``): ``<root>/cache/<key hash>/`` holds
an identical case's row (``row.parquet``) and trajectory (``trajectory.npz``).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
import threading
from pathlib import Path

from mbh._harness.common.status import CaseStatus
from mbh._harness.model.trajectory import Trajectory
from mbh._harness.store.files import write_table
from mbh._harness.store.location import root_or_default
from mbh._harness.store.problems import DAMAGE, writing
from mbh._harness.store.rows import read_table, row_table
from mbh._harness.store.schema import CASE_COLUMNS, SCHEMA_VERSION
from mbh._harness.store.trajectory_files import load_trajectory, save_trajectory

__all__ = ["UNCACHED_STATUSES", "CaseCache"]

#: Statuses the cache never keeps: they describe the machine's load, not the case.
UNCACHED_STATUSES = (CaseStatus.TIMEOUT, CaseStatus.CRASHED)


class CaseCache:
    """Rows and trajectories of finished cases, reusable by any run (``mbh run --reuse``).

    An entry is keyed by (scenario content hash, adapter name, adapter version, method string,
    dt, t_end, settings) and lives in ``<root>/cache/<key hash>/`` (row.parquet + trajectory.npz),
    written in a temp folder and renamed into place.  Rows with a status of
    :data:`UNCACHED_STATUSES` are not kept.

    Parameters
    ----------
    root : Path, optional
        Results root (default :func:`~mbh._harness.store.location.results_root`).
    """

    def __init__(self, root: Path | None = None):
        self.folder = root_or_default(root) / "cache"

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
            row = read_table(entry / "row.parquet", SCHEMA_VERSION).to_pylist()[0]
            trajectory = load_trajectory(trajectory_path) if trajectory_path.is_file() else None
        except DAMAGE:  # a damaged entry is a miss: the case runs again
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
        with writing(temp), contextlib.ExitStack() as cleanup:
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
        write_table(temp / "row.parquet", row_table({**stored, "run_id": run_id}, CASE_COLUMNS))
        if trajectory is not None:
            save_trajectory(temp / "trajectory.npz", trajectory)
        try:
            os.rename(temp, entry)
        except OSError:
            if not entry.is_dir():
                raise
