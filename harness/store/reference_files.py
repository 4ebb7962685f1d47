"""The files of verified references: where they live, how they are written and when a stored one
still belongs to a scene.

A reference is kept as two files named ``<scene>-<content hash[:16]>-v<version>``: the body
states on the reference grid (``.npz``: times, position, quaternion, velocity, angular velocity)
and its metadata (``.json``: the scene's name and hash, the version, the grid step, the two
routes, their agreement and cost, and the independent route's agreement).  A refused build is
recorded beside them (``.refused.json``).

Shipped scenes come with their references (``scenarios/references``, inside the installed
package); a reference built on this machine goes to the user cache (:func:`cache_dir`), never into
the package.  The references are built by :mod:`mbh._harness.references.build`; reports read
them through :func:`stored_reference` and never build one.

Files are written atomically (a unique temporary file moved into place with ``os.replace``),
data first and metadata last, so concurrent processes can share the folder.
"""

from __future__ import annotations

import json
import os
import tempfile
import zipfile
from pathlib import Path

import numpy as np

from mbh._harness.common.kept_files import read_kept
from mbh._harness.common.locations import shipped, user_cache
from mbh._harness.model.mechanism import Mechanism
from mbh._harness.model.timegrid import GRID_STEP
from mbh._harness.model.trajectory import Trajectory

__all__ = ["REFERENCE_VERSION", "AGREEMENT_LIMIT", "ARRAYS", "CACHE_ENV", "cache_dir",
           "search_dirs", "reference_grid",
           "reference_paths", "refusal_path", "replace_atomically", "read_unchecked",
           "read_reference", "write_reference", "stale_reason", "stored_reference"]

#: Version of the reference builder; bumping it (a formulation change) retires every stored file.
#: 4: every reference names its independent route and that route's agreement.
REFERENCE_VERSION = 4
#: Largest difference allowed between the two routes of a reference, m or rad.
AGREEMENT_LIMIT = 1e-9
#: The arrays of a stored reference trajectory.
ARRAYS = ("times", "position", "quaternion", "velocity", "angular_velocity")


#: Environment variable naming the one folder references are read from and written to.
CACHE_ENV = "MBH_CACHE_DIR"


def cache_dir() -> Path:
    """Where references built here are written: ``$MBH_CACHE_DIR``, else ``references`` in the
    user cache (:func:`mbh._harness.common.locations.user_cache`)."""
    configured = os.environ.get(CACHE_ENV)
    return Path(configured) if configured else user_cache() / "references"


def search_dirs() -> tuple[Path, ...]:
    """Folders a reference is read from, the first holding it wins: ``$MBH_CACHE_DIR`` alone when
    set, else the user cache's and then the shipped ``scenarios/references``."""
    if os.environ.get(CACHE_ENV):
        return (cache_dir(),)
    return cache_dir(), shipped("scenarios") / "references"


def reference_grid(mech: Mechanism) -> np.ndarray:
    """The dense sample grid, shape (n,), s: every GRID_STEP from 0 to the duration."""
    return np.arange(int(round(mech.duration / GRID_STEP)) + 1) * GRID_STEP


def _paths_in(folder: Path, mech: Mechanism) -> tuple[Path, Path]:
    stem = f"{mech.name}-{mech.content_hash[:16]}-v{REFERENCE_VERSION}"
    return folder / f"{stem}.npz", folder / f"{stem}.json"


def reference_paths(mech: Mechanism) -> tuple[Path, Path]:
    """The data (.npz) and metadata (.json) files of ``mech``'s reference: in the first of
    :func:`search_dirs` that holds its metadata, else where a build writes them
    (:func:`cache_dir`)."""
    for folder in search_dirs():
        paths = _paths_in(folder, mech)
        if paths[1].is_file():
            return paths
    return _paths_in(cache_dir(), mech)


def refusal_path(mech: Mechanism) -> Path:
    """Where a refused build of ``mech`` is recorded (in :func:`cache_dir`)."""
    return _paths_in(cache_dir(), mech)[1].with_suffix(".refused.json")


def replace_atomically(path: Path, write) -> None:
    """Call ``write(binary file)`` on a unique temporary file next to ``path``, then move it onto
    ``path`` with ``os.replace`` (creating ``path``'s folder if needed); the temporary file is
    removed if anything fails."""
    path.parent.mkdir(parents=True, exist_ok=True)
    handle = tempfile.NamedTemporaryFile(dir=path.parent, prefix=f".{path.name}.",
                                         suffix=".tmp", delete=False)
    try:
        with handle:
            write(handle)
        os.chmod(handle.name, 0o644)  # readable by all, as a plainly written file (not 0600)
        os.replace(handle.name, path)
    except BaseException:
        Path(handle.name).unlink(missing_ok=True)
        raise


def write_reference(mech: Mechanism, trajectory: Trajectory, info: dict) -> None:
    """Store ``mech``'s reference and its metadata (data first, metadata last) in
    :func:`cache_dir`; raises OSError."""
    data_path, info_path = _paths_in(cache_dir(), mech)
    replace_atomically(data_path, lambda handle: np.savez_compressed(
        handle, **{key: getattr(trajectory, key) for key in ARRAYS}))
    replace_atomically(info_path, lambda handle: handle.write(json.dumps(info, indent=2).encode()))


def read_unchecked(data_path: Path, info_path: Path) -> tuple[Trajectory, dict] | None:
    """The stored (trajectory, info) as they are on disk, or None when a file is missing or
    unreadable.  The trajectory's arrays are read-only: the warm template's read is kept for every
    case forked from it (:mod:`mbh._harness.common.kept_files`), and none may change what the next reads.
    """
    return read_kept("reference", (data_path, info_path),
                     lambda: _read_files(data_path, info_path))


def _read_files(data_path: Path, info_path: Path) -> tuple[Trajectory, dict] | None:
    """:func:`read_unchecked` from the files themselves."""
    try:
        info = json.loads(info_path.read_text())
        with np.load(data_path) as data:
            trajectory = Trajectory(**{key: data[key] for key in ARRAYS})
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
        return None
    for key in ARRAYS:
        getattr(trajectory, key).flags.writeable = False
    return trajectory, info


def read_reference(mech: Mechanism, routes=None) -> tuple[Trajectory, dict] | None:
    """``mech``'s stored (trajectory, info), or None when a file is missing, unreadable or stale
    (:func:`stale_reason`; ``routes``: the two (method, step) routes the builder uses now, or None
    to accept the stored ones)."""
    stored = read_unchecked(*reference_paths(mech))
    if stored is None:
        return None
    trajectory, info = stored
    return None if stale_reason(mech, info, trajectory, routes) else stored


def stored_reference(mech: Mechanism) -> Trajectory | None:
    """``mech``'s stored reference trajectory, or None if none is stored for it (never builds)."""
    stored = read_reference(mech)
    return None if stored is None else stored[0]


def stale_reason(mech: Mechanism, info: dict, trajectory: Trajectory, routes=None) -> str:
    """Why a stored reference does not belong to ``mech`` ('' when it does): scenario name,
    content hash, version, grid step, routes (when given), the routes' and the independent
    route's agreement within :data:`AGREEMENT_LIMIT`, and arrays on :func:`reference_grid`."""
    expected = {"scenario": mech.name, "content_hash": mech.content_hash,
                "version": REFERENCE_VERSION, "grid_step": GRID_STEP}
    for key, value in expected.items():
        if info.get(key) != value:
            return f"{key} is {info.get(key)!r}, expected {value!r}"
    if routes is not None:
        stored = [info.get("route_a"), info.get("route_b")]
        expected_routes = [list(route) for route in routes]
        if stored != expected_routes:
            return f"routes {stored!r} are not {expected_routes!r}"
    independent = info.get("independent", {}).get("difference", {})
    for what, agreement in (("route agreement", info.get("agreement", {}).get("max")),
                            ("independent route's agreement", independent.get("max"))):
        if not isinstance(agreement, (int, float)) or not agreement <= AGREEMENT_LIMIT:
            return f"{what} {agreement!r} is not within {AGREEMENT_LIMIT:g}"
    grid = reference_grid(mech)
    n_bodies = len(mech.bodies)
    shapes = {"times": (grid.size,), "position": (grid.size, n_bodies, 3),
              "quaternion": (grid.size, n_bodies, 4), "velocity": (grid.size, n_bodies, 3),
              "angular_velocity": (grid.size, n_bodies, 3)}
    for key, shape in shapes.items():
        if getattr(trajectory, key).shape != shape:
            return f"{key} has shape {getattr(trajectory, key).shape}, expected {shape}"
    if np.abs(trajectory.times - grid).max() > 1e-9:
        return "sample times are not the reference grid"
    return ""
