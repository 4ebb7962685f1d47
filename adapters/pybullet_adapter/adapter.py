"""The PyBullet adapter: its methods (solver settings), the stepping loop with divergence checks,
and the run that turns an engine failure into a status.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from adapters.base import Adapter, MethodSpec
from adapters.pybullet_adapter.build import PybulletModel, build_model
from adapters.pybullet_adapter.loads import _apply_loads, _needs_body_loads, _tree_actuation
from adapters.pybullet_adapter.quiet import pybullet
from adapters.pybullet_adapter.state import _read_states
from adapters.pybullet_adapter.world import bullet_world
from harness.model import Mechanism
from harness.trajectory import BodyStates, Trajectory

#: A run has diverged when a centre of mass leaves a ball this many times the mechanism's size.
_DIVERGED_SCALE = 1e3

#: PyBullet's own defaults (PhysicsServerCommandProcessor and btContactSolverInfo), checked by the
#: test that runs ``default`` with and without setting them and compares bit for bit.
_ENGINE_DEFAULTS = {
    "numSolverIterations": 50,
    "erp": 0.2,
    "contactERP": 0.08,
    "frictionERP": 0.2,
    "globalCFM": 0.0,
    "numSubSteps": 0,
    "solverResidualThreshold": 1e-7,
    "constraintSolverType": pybullet.CONSTRAINT_SOLVER_LCP_SI,
    "useSplitImpulse": True,
    "warmStartingFactor": 0.1,
    "numNonContactInnerIterations": 1,
}
#: The most accurate solver settings measured at a given step (see the report): full error
#: reduction of the loop closure, more iterations, no residual early exit.  The MLCP solvers
#: (PGS, Dantzig) do worse on these loops: PGS blows up, Dantzig leaves the loop open.
_BEST = {**_ENGINE_DEFAULTS, "numSolverIterations": 200, "erp": 1.0, "solverResidualThreshold": 0.0}
#: ``best`` with ten Bullet sub-steps per step (ten times the work per step).
_SUBSTEPS = {**_BEST, "numSubSteps": 10}


def _diverged(states: BodyStates, limit: float) -> bool:
    arrays = (states.position, states.quaternion, states.velocity, states.angular_velocity)
    if not all(np.all(np.isfinite(a)) for a in arrays):
        return True
    return bool(np.max(np.linalg.norm(states.position, axis=1)) > limit)


def _check_times(dt: float, t_end: float, sample_times) -> np.ndarray:
    """``sample_times`` as a float array, shape (n_samples,); a ValueError names a bad argument."""
    if not (dt > 0 and math.isfinite(dt)):
        raise ValueError(f"dt must be a positive finite number, got {dt!r}")
    if not (t_end >= 0 and math.isfinite(t_end)):
        raise ValueError(f"t_end must be a non-negative finite number, got {t_end!r}")
    times = np.asarray(sample_times, dtype=float)
    if times.ndim != 1 or np.any(np.diff(times) <= 0) or np.any(times < 0) \
            or np.any(times > t_end + 0.5 * dt):
        raise ValueError("sample_times must be increasing times in [0, t_end]")
    return times


@dataclass
class _Progress:
    """What a run has reached: samples, steps taken and stepping wall time (s)."""

    samples: list
    step: int = 0
    wall: float = 0.0


def _advance(model: PybulletModel, uid: int, client: int, loads: tuple, target: int,
             progress: _Progress) -> None:
    """Step until ``progress.step == target``, timing the loads and the stepping only."""
    actuation, needs_state = loads
    while progress.step < target:
        start = time.perf_counter()
        _apply_loads(model, uid, client, actuation, needs_state)
        pybullet.stepSimulation(physicsClientId=client)
        progress.wall += time.perf_counter() - start
        progress.step += 1


def _stepping(model: PybulletModel, uid: int, client: int, sample_steps: np.ndarray,
              n_steps: int, progress: _Progress) -> str:
    """Step through every sample and on to ``n_steps``; returns "ok" or "diverged"."""
    loads = (_tree_actuation(model), _needs_body_loads(model))
    limit = _DIVERGED_SCALE * max(model.size, 1.0)
    for target in sample_steps:
        _advance(model, uid, client, loads, int(target), progress)
        states = _read_states(model, uid, client)
        if _diverged(states, limit):
            return "diverged"
        progress.samples.append(states)
    _advance(model, uid, client, loads, n_steps, progress)
    return "ok"


def _run(model: PybulletModel, params: dict, dt: float, sample_times: np.ndarray,
         n_steps: int) -> Trajectory:
    """Step a fresh world and sample it.

    An exception raised by the engine ends the run as ``failed`` with the samples reached.
    """
    progress = _Progress(samples=[])
    sample_steps = np.rint(sample_times / dt).astype(int)
    reason = ""
    try:
        with bullet_world(model, params, dt) as world:
            status = _stepping(model, world.body, world.client, sample_steps, n_steps, progress)
    except Exception as error:  # an engine failure is data (DESIGN.md rule 5)
        status, reason = "failed", f"{type(error).__name__}: {error}"
    if status == "diverged":
        reason = "state non-finite or a centre of mass beyond " \
                 f"{_DIVERGED_SCALE * max(model.size, 1.0):g} m from the origin"
    return Trajectory.from_samples(
        sample_times, progress.samples, status=status, reason=reason,
        failure_time=None if status == "ok" else progress.step * dt,
        wall_time_s=progress.wall, steps=progress.step, notes=list(model.notes),
        counters={"substeps": progress.step * max(1, int(params["numSubSteps"]))},
    )


class PybulletAdapter(Adapter):
    """PyBullet (Bullet's Featherstone multibody with sequential-impulse or LCP constraints)."""

    name = "pybullet"

    def version(self) -> str:
        from importlib.metadata import version
        return f"pybullet {version('pybullet')}"

    def methods(self) -> list[MethodSpec]:
        return [
            MethodSpec("default", "PyBullet's own solver settings at the given step "
                       "(setPhysicsEngineParameter defaults)", dict(_ENGINE_DEFAULTS)),
            MethodSpec("best", "most accurate settings measured: erp = 1 (full error reduction "
                       "of the loop closure), 200 iterations, no residual early exit",
                       dict(_BEST)),
            MethodSpec("substeps", "best with numSubSteps = 10: Bullet divides every step in ten",
                       dict(_SUBSTEPS)),
        ]

    def build(self, mechanism: Mechanism) -> PybulletModel:
        return build_model(mechanism)

    def simulate(self, model: PybulletModel, method: str, dt: float, t_end: float,
                 sample_times: np.ndarray) -> Trajectory:
        _, params = self.method_spec(method)
        times = _check_times(dt, t_end, sample_times)
        return _run(model, params, dt, times, int(round(t_end / dt)))
