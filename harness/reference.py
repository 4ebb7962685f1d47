"""Verified reference solutions, cached on disk by scenario content hash.

A reference is the in-house formulation's most accurate configuration, computed by two routes on
the same dense time grid, both the index-1 augmented form with direct position and velocity
projection after every step (002 eq. 77, 127, 137) at Δt = 5e-5 s, integrated by two different
method families:

* route A (:data:`ROUTE_A`): the classical Runge–Kutta RK4 on the first-order system;
* route B (:data:`ROUTE_B`): the Runge–Kutta–Nyström RKN4 on the second-order system.

Their largest difference over the whole run — every position-level output and every body's centre
of mass, in rad and m — is stored with the reference and must not exceed :data:`AGREEMENT_LIMIT`.
Route A's trajectory is the reference.  The formulation itself is checked independently elsewhere:
the planar and spatial four-bar models agree (tests), the engines in joint coordinates agree
(Pinocchio to ~4e-11 rad), and a third, informational route stored here runs SUNDIALS IDA on the
stabilised index-2 DAE (:data:`DAE_CHECK`).  IDA's corrector fails below rtol ≈ 1e-13, which leaves
it ~6e-10 from route A on the four-bar and ~1e-7 on the fast-spinning slider-cranks, so it is
reported, not required.  Rejected as routes (measured on the 8 s spatial slider-crank, crank turning
42 rad): adaptive DOP853 on the partitioned form at rtol 3e-14 (1.7e-9 off) and fixed-step
partitioning with its split switched late (RK4 or RKN4 at 5e-5: 8e-8 and 6e-9 off; the reduced
ODE steepens near a fold of the independent coordinate, see :mod:`adapters.inhouse.partition`,
whose default now switches at a 1 % conditioning advantage).

Shipped references live in ``scenarios/references`` (``MBH_CACHE_DIR`` overrides it); a file is
keyed by the scenario's content hash and :data:`REFERENCE_VERSION`, so editing a scenario, or
bumping the version when the formulation changes, rebuilds it.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from harness.model import Mechanism
from harness.outputs import output_series
from harness.trajectory import Trajectory

REFERENCE_VERSION = 3
GRID_STEP = 1e-3
AGREEMENT_LIMIT = 1e-9
#: (method, step) of each route; IDA's step is only its first-step hint.
ROUTE_A = ("rk4+direct:proj_tol=1e-14", 5e-5)
ROUTE_B = ("rkn4+direct:proj_tol=1e-14", 5e-5)
DAE_CHECK = ("ida:rtol=1e-13,atol=1e-13,max_steps=5000000", GRID_STEP)
_ARRAYS = ("times", "position", "quaternion", "velocity", "angular_velocity")


class ReferenceError(RuntimeError):
    """The two routes did not agree, or a route failed; the message has the numbers."""


def cache_dir() -> Path:
    default = Path(__file__).resolve().parent.parent / "scenarios" / "references"
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


def _run_route(mech: Mechanism, route: tuple[str, float], grid: np.ndarray) -> Trajectory:
    from adapters import get_adapter

    method, step = route
    trajectory = get_adapter("inhouse").simulate(mech, method, step, mech.duration, grid)
    if trajectory.status != "ok" or trajectory.n_samples != grid.size:
        raise ReferenceError(f"{mech.name}: reference route {method} (dt {step:g}) ended "
                             f"{trajectory.status} at t = {trajectory.failure_time}: "
                             f"{trajectory.reason}")
    return trajectory


def _cost(trajectory: Trajectory) -> dict:
    return {"wall_time_s": trajectory.wall_time_s, "steps": trajectory.steps, **trajectory.counters}


def _dae_check(mech: Mechanism, route_a: Trajectory, grid: np.ndarray) -> dict:
    """Difference between IDA and route A, or why IDA did not finish (informational)."""
    try:
        dae = _run_route(mech, DAE_CHECK, grid)
    except ReferenceError as error:
        return {"method": DAE_CHECK[0], "status": "failed", "reason": str(error)}
    return {"method": DAE_CHECK[0], "status": "ok", "difference": route_difference(mech, route_a, dae),
            "cost": _cost(dae)}


def build_reference(mech: Mechanism) -> tuple[Trajectory, dict]:
    """Compute both routes, their agreement and the DAE check (no cache); raises ReferenceError
    when the routes differ by more than :data:`AGREEMENT_LIMIT`."""
    grid = reference_grid(mech)
    route_a = _run_route(mech, ROUTE_A, grid)
    route_b = _run_route(mech, ROUTE_B, grid)
    agreement = route_difference(mech, route_a, route_b)
    info = {"scenario": mech.name, "content_hash": mech.content_hash,
            "version": REFERENCE_VERSION, "route_a": list(ROUTE_A), "route_b": list(ROUTE_B),
            "grid_step": GRID_STEP, "agreement": agreement,
            "route_a_cost": _cost(route_a), "route_b_cost": _cost(route_b),
            "dae_check": _dae_check(mech, route_a, grid)}
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
