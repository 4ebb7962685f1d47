"""Verified reference solutions, cached on disk by scenario content hash.

A reference is the in-house formulation's most accurate configuration, computed by two independent
routes on the same dense time grid:

* route A: coordinate partitioning (the constraints hold to Newton tolerance at every evaluation)
  integrated by DOP853 at rtol = atol = 1e-12 (:data:`ROUTE_A`);
* route B: SUNDIALS IDA on the stabilised index-2 (GGL) DAE in all coordinates (:data:`ROUTE_B`),
  at rtol = atol = 1e-13 (at 1e-12 it stays 1.3–4.2e-9 from DOP853 on the four-bar; tighter than
  1e-13 its corrector fails).

Their largest difference over the whole run — every named output and every body's centre-of-mass
position, in rad and m — is stored with the reference and must not exceed
:data:`AGREEMENT_LIMIT`.  Route A's trajectory is the reference.

The cache lives in ``.cache/references`` at the repository root (``MBH_CACHE_DIR`` overrides it);
a file is keyed by the scenario's content hash and :data:`REFERENCE_VERSION`, so editing a
scenario, or bumping the version when the formulation changes, rebuilds it.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from harness.model import Mechanism
from harness.outputs import output_series
from harness.trajectory import Trajectory

REFERENCE_VERSION = 1
GRID_STEP = 1e-3
AGREEMENT_LIMIT = 1e-9
ROUTE_A = "dop853+partition:rtol=1e-12,atol=1e-12"
ROUTE_B = "ida:rtol=1e-13,atol=1e-13,max_steps=5000000"
_ARRAYS = ("times", "position", "quaternion", "velocity", "angular_velocity")


class ReferenceError(RuntimeError):
    """The two routes did not agree, or a route failed; the message has the numbers."""


def cache_dir() -> Path:
    default = Path(__file__).resolve().parent.parent / ".cache" / "references"
    return Path(os.environ.get("MBH_CACHE_DIR", default))


def reference_grid(mech: Mechanism) -> np.ndarray:
    """The dense sample grid, shape (n,), s: every GRID_STEP from 0 to the duration."""
    return np.arange(int(round(mech.duration / GRID_STEP)) + 1) * GRID_STEP


def _paths(mech: Mechanism) -> tuple[Path, Path]:
    stem = f"{mech.name}-{mech.content_hash[:16]}-v{REFERENCE_VERSION}"
    return cache_dir() / f"{stem}.npz", cache_dir() / f"{stem}.json"


_POSITION_LEVEL = ("joint_angle", "joint_position", "position")


def route_difference(mech: Mechanism, a: Trajectory, b: Trajectory) -> dict:
    """Largest differences between two trajectories on the same grid.

    ``max`` covers the position-level quantities the agreement limit applies to (outputs in rad
    or m and every body's centre of mass, m); velocity-level outputs (rad/s, m/s) are reported
    under ``velocity_outputs`` for information.
    """
    def difference(name):
        return float(np.abs(output_series(mech, a, name) - output_series(mech, b, name)).max())

    position = {o.name: difference(o.name) for o in mech.outputs if o.kind in _POSITION_LEVEL}
    velocity = {o.name: difference(o.name) for o in mech.outputs if o.kind not in _POSITION_LEVEL}
    bodies = float(np.abs(a.position - b.position).max())
    return {"outputs": position, "velocity_outputs": velocity, "body_position_m": bodies,
            "max": max([*position.values(), bodies])}


def _run_route(mech: Mechanism, method: str, grid: np.ndarray) -> Trajectory:
    from adapters import get_adapter

    trajectory = get_adapter("inhouse").simulate(mech, method, GRID_STEP, mech.duration, grid)
    if trajectory.status != "ok" or trajectory.n_samples != grid.size:
        raise ReferenceError(f"{mech.name}: reference route {method} ended {trajectory.status} "
                             f"at t = {trajectory.failure_time}: {trajectory.reason}")
    return trajectory


def build_reference(mech: Mechanism) -> tuple[Trajectory, dict]:
    """Compute both routes and their agreement (no cache); raises ReferenceError beyond the limit."""
    grid = reference_grid(mech)
    route_a = _run_route(mech, ROUTE_A, grid)
    route_b = _run_route(mech, ROUTE_B, grid)
    agreement = route_difference(mech, route_a, route_b)
    info = {"scenario": mech.name, "content_hash": mech.content_hash,
            "version": REFERENCE_VERSION, "route_a": ROUTE_A, "route_b": ROUTE_B,
            "grid_step": GRID_STEP, "agreement": agreement,
            "route_a_cost": {"wall_time_s": route_a.wall_time_s, **route_a.counters},
            "route_b_cost": {"wall_time_s": route_b.wall_time_s, **route_b.counters}}
    if agreement["max"] > AGREEMENT_LIMIT:
        raise ReferenceError(f"{mech.name}: reference routes disagree by {agreement['max']:.3g} "
                             f"> {AGREEMENT_LIMIT:g} ({json.dumps(agreement)})")
    return route_a, info


def reference_trajectory(mech: Mechanism) -> Trajectory:
    """The verified reference of ``mech``, from the cache or built (and cached) now."""
    return load_or_build(mech)[0]


def reference_info(mech: Mechanism) -> dict:
    """The stored agreement and cost of ``mech``'s reference."""
    return load_or_build(mech)[1]


def load_or_build(mech: Mechanism) -> tuple[Trajectory, dict]:
    data_path, info_path = _paths(mech)
    if data_path.exists() and info_path.exists():
        with np.load(data_path) as data:
            trajectory = Trajectory(**{key: data[key] for key in _ARRAYS})
        return trajectory, json.loads(info_path.read_text())
    trajectory, info = build_reference(mech)
    data_path.parent.mkdir(parents=True, exist_ok=True)
    temporary = data_path.with_suffix(".tmp.npz")
    np.savez_compressed(temporary, **{key: getattr(trajectory, key) for key in _ARRAYS})
    temporary.replace(data_path)
    info_path.write_text(json.dumps(info, indent=2))
    return trajectory, info
