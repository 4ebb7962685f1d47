"""A run's manifest (``<run>/manifest.json``): what a new run records, reading one back migrated
to the current schema (or a stand-in when it is damaged), and the listing of the stored runs by
their manifests.
"""

from __future__ import annotations

import datetime as _dt
import json
from pathlib import Path

from mbh._harness.common.environment import git_state, machine, package_versions
from mbh._harness.common.status import FINISHED_RUN_STATUSES, RunStatus
from mbh._harness.store.location import root_or_default
from mbh._harness.store.problems import StoreError, StoreProblem
from mbh._harness.store.schema import SCHEMA_VERSION, SchemaError, migrate_manifest

__all__ = ["MANIFEST", "timestamp", "new_manifest", "manifest_of", "list_runs", "latest_run"]

#: The manifest's file name in a run folder.
MANIFEST = "manifest.json"

#: Keys every manifest has, each a string (what listing and opening a run read first).
_MANIFEST_KEYS = ("run_id", "campaign", "started", "status")


def timestamp() -> str:
    """The current UTC time as the manifest records times (ISO 8601, microseconds)."""
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="microseconds")


def new_manifest(run_id: str, campaign, started: _dt.datetime,
                 scenario_hashes: dict[str, str]) -> dict:
    """The manifest of a run that starts: status ``running``, the campaign (a
    :class:`mbh._harness.run.spec.Campaign`: its name, path, text and cases), the start time
    ``started`` (UTC), the content hash of each scenario the run uses, and this machine's git
    state, package versions and description."""
    return {
        "schema_version": SCHEMA_VERSION, "created_schema_version": SCHEMA_VERSION,
        "run_id": run_id, "campaign": campaign.name, "campaign_path": str(campaign.path),
        "campaign_text": campaign.text, "n_cases": len(campaign.cases),
        "started": started.isoformat(timespec="microseconds"), "ended": None,
        "status": RunStatus.RUNNING, "git": git_state(), "packages": package_versions(),
        "machine": machine(), "scenario_hashes": scenario_hashes, "calibration_s": None,
    }


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
    ``unreadable``, the problem under ``problems``; parts are read at their own version."""
    return {"run_id": folder.name, "campaign": "", "started": "", "ended": None,
            "status": RunStatus.UNREADABLE, "n_cases": None, "schema_version": SCHEMA_VERSION,
            "created_schema_version": SCHEMA_VERSION, "calibration_s": None,
            "problems": [str(problem)]}


def manifest_of(folder: Path, tolerated=(StoreError,)) -> tuple[dict, StoreProblem | None]:
    """The manifest of the run folder ``folder`` and None, or (for an error of ``tolerated``)
    the stand-in and the problem.

    Raises
    ------
    SchemaError
        When a newer mbh wrote it (unless ``tolerated`` holds SchemaError).
    """
    path = folder / MANIFEST
    try:
        return _read_manifest(path), None
    except tolerated as error:
        problem = StoreProblem(str(path), str(error).removeprefix(f"{path}: "))
        return _unreadable_manifest(folder, problem), problem


def _run_folders(root: Path) -> list[Path]:
    if not root.is_dir():
        return []
    return [path for path in root.iterdir() if (path / MANIFEST).is_file()]


def list_runs(root: Path | None = None) -> list[dict]:
    """Manifests of every run under ``root`` (migrated), oldest start first; a run whose
    manifest cannot be read comes first, as a stand-in with status ``unreadable`` and the
    problem under ``problems``."""
    manifests = [manifest_of(path, (StoreError, SchemaError))[0]
                 for path in _run_folders(root_or_default(root))]
    return sorted(manifests, key=lambda m: (m["started"], m["run_id"]))


def latest_run(campaign: str, root: Path | None = None, *, before: str | None = None,
               statuses: tuple[RunStatus, ...] = FINISHED_RUN_STATUSES) -> str | None:
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
