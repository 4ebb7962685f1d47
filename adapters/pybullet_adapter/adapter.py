"""The PyBullet adapter: its methods (solver settings) and its stepper, driven by the shared run
loop (:meth:`mbh._adapters.base.Adapter.simulate`), with Bullet's extra divergence check.
"""

from __future__ import annotations

import contextlib
import time

import numpy as np

from mbh._adapters.base import Adapter, MethodSpec, RunGrid, Stepper
from mbh._adapters.pybullet_adapter.build import PybulletModel, build_model
from mbh._adapters.pybullet_adapter.loads import _loaded_steps
from mbh._adapters.pybullet_adapter.quiet import pybullet
from mbh._adapters.pybullet_adapter.redundancy import redundancy_notes
from mbh._adapters.pybullet_adapter.state import _read_states
from mbh._adapters.pybullet_adapter.world import bullet_world
from mbh._harness.model.mechanism import Mechanism
from mbh._harness.model.trajectory import BodyStates

#: A run has diverged when a centre of mass leaves a ball this many times the mechanism's size,
#: or a speed exceeds this many times the size per second (on top of the common check of
#: :func:`mbh._adapters.base.divergence_reason`: non-finite or beyond 1e8).  1e3 cut physical runs:
#: Andrews' squeezer (size 0.2 m, so 1e3 rad/s) really spins its crank at 1.1e3 rad/s; an
#: unstable Bullet run grows exponentially and passes 1e5 a few steps after 1e3.
_DIVERGED_SCALE = 1e5

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
#: The most accurate solver settings found at a given step (see the report): full error
#: reduction of the loop closure, more iterations.  The MLCP solvers (PGS, Dantzig) do worse on
#: these loops: PGS blows up, Dantzig leaves the loop open.  The residual early exit stays at
#: Bullet's default 1e-7: threshold 0 is no more accurate (errors and drifts the same to 0.1 %)
#: and three times slower per step (figures: docs/measurements.md, section "Engines").
_BEST = {**_ENGINE_DEFAULTS, "numSolverIterations": 200, "erp": 1.0}
#: ``best`` with ten Bullet sub-steps per step (ten times the work per step).
_SUBSTEPS = {**_BEST, "numSubSteps": 10}


#: The note naming the limit every run meets: its order.
ORDER_NOTE = ("engine limit: Bullet steps semi-implicit Euler, first order, and closes loops at "
              "velocity level, so the error falls as dt (10× per 10× smaller step) where the "
              "fourth-order methods' falls as dt⁴ (docs/measurements.md, \"Engine settings on "
              "hard loops\")")


class _BulletStepper(Stepper):
    """One Bullet world stepped at the fixed step ``dt``; samples are read after step
    ``round(t / dt)``, the loads re-applied before every step.

    Attributes
    ----------
    take_steps : callable
        ``take_steps(count)`` takes ``count`` steps with their loads and no checks
        (:func:`~mbh._adapters.pybullet_adapter.loads._loaded_steps`); divergence is checked on the
        samples (:meth:`divergence`).
    """

    def __init__(self, model: PybulletModel, params: dict, grid: RunGrid):
        super().__init__()
        self.model, self.grid = model, grid
        self.substeps = max(1, int(params["numSubSteps"]))
        self.limit = _DIVERGED_SCALE * max(model.size, 1.0)
        with contextlib.ExitStack() as stack:
            world = stack.enter_context(bullet_world(model, params, grid.dt))
            self.notes = [*redundancy_notes(model, world), *model.notes, ORDER_NOTE]
            self._exit = stack.pop_all()  # the world stays open until close()
        self.uid, self.client = world.body, world.client
        self.take_steps = _loaded_steps(model, self.uid, self.client)

    def _step_to(self, t: float) -> None:
        count = self.grid.steps(t) - self.steps
        if count > 0:
            self.take_steps(count)
            self.steps += count

    def _states(self, t: float) -> BodyStates:
        return _read_states(self.model, self.uid, self.client)

    def divergence(self, states: BodyStates) -> str | None:
        """A centre of mass beyond ``limit`` m from the origin, or a linear (m/s) or angular
        (rad/s) speed beyond ``limit`` per second."""
        for name, unit in (("position", "m"), ("velocity", "m/s"), ("angular_velocity", "rad/s")):
            largest = float(np.max(np.linalg.norm(getattr(states, name), axis=1), initial=0.0))
            if largest > self.limit:
                return (f"{name.replace('_', ' ')} {largest:.3g} {unit} beyond "
                        f"{_DIVERGED_SCALE:g} × the mechanism's size ({self.limit:g})")
        return None

    def counters(self) -> dict:
        return {"substeps": self.steps * self.substeps}

    def close(self) -> None:
        self._exit.close()


#: Position coordinates of each Bullet joint type (``getJointInfo``'s jointType).
_JOINT_COORDINATES = {pybullet.JOINT_REVOLUTE: 1, pybullet.JOINT_PRISMATIC: 1,
                      pybullet.JOINT_SPHERICAL: 4, pybullet.JOINT_FIXED: 0}
#: Constraint rows of each Bullet user-constraint type (``getConstraintInfo``'s jointType).
_CONSTRAINT_ROWS = {pybullet.JOINT_POINT2POINT: 3, pybullet.JOINT_FIXED: 6,
                    pybullet.JOINT_GEAR: 1}


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
                       "of the loop closure), 200 iterations, Bullet's residual early exit "
                       "(1e-7; 0 measured no more accurate, 3× slower)", dict(_BEST)),
            MethodSpec("substeps", "best with numSubSteps = 10: Bullet divides every step in ten",
                       dict(_SUBSTEPS)),
        ]

    def build(self, mechanism: Mechanism) -> PybulletModel:
        return build_model(mechanism)

    def model_size(self, model: PybulletModel) -> dict:
        """Position coordinates of the Bullet multibody (per joint: 1 revolute or prismatic,
        4 spherical, 0 fixed, read from ``getJointInfo``) and the rows of its cut-joint
        constraints (3 per point-to-point ``getConstraintInfo``); redundant rows are the closure
        equations beyond the cut joints' class in the mechanism's dimension."""
        with bullet_world(model, None, 0.01) as world:
            kinds = [pybullet.getJointInfo(world.body, j, physicsClientId=world.client)[2]
                     for j in range(pybullet.getNumJoints(world.body,
                                                          physicsClientId=world.client))]
            constraints = [pybullet.getConstraintInfo(c, physicsClientId=world.client)[4]
                           for c in world.constraints]
        coordinates = sum(_JOINT_COORDINATES[kind] for kind in kinds)
        rows = sum(_CONSTRAINT_ROWS[kind] for kind in constraints)
        return {"coordinates": coordinates, "constraint_equations": rows,
                "redundant_equations": model.tree.redundant_closure_equations,
                "notes": f"Bullet multibody with {len(kinds)} joint(s), {coordinates} position "
                         f"coordinates; {len(constraints)} point-to-point constraint(s) with "
                         f"{rows} rows closing the loops"}

    def bare_loop(self, model: PybulletModel, method: str, dt: float, n_steps: int) -> float:
        """Bullet's loop alone: ``n_steps`` calls of ``stepSimulation``, each after the loads
        Bullet needs re-applied (it clears them every step), in the world :meth:`simulate`
        builds, without samples or checks."""
        spec, params = self.method_spec(method)
        stepper = self._start(model, spec, params, RunGrid(dt, n_steps * dt, np.zeros(1), True))
        try:
            began = time.perf_counter()
            stepper.take_steps(n_steps)
            return time.perf_counter() - began
        finally:
            stepper.close()

    def _start(self, model: PybulletModel, spec: MethodSpec, params: dict,
               grid: RunGrid) -> _BulletStepper:
        return _BulletStepper(model, params, grid)
