"""The Exudyn adapter: the harness's contract over :mod:`.methods` and :mod:`.system`.  ``build``
only checks that Exudyn can represent the mechanism; every run builds a fresh
:class:`~mbh._adapters.exudyn_adapter.system.ExudynSystem`, with Exudyn's console output off, and is
driven by the shared run loop (:meth:`mbh._adapters.base.Adapter.simulate`) through
:class:`_ExudynStepper`.
"""

from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass

import exudyn as exu
import numpy as np

from mbh._adapters.base import Adapter, MethodSpec, RunFailure, RunGrid, Stepper, UnsupportedCase
from mbh._adapters.exudyn_adapter.methods import (
    _BEST,
    _GENALPHA_PARAMS,
    _NEWMARK_PARAMS,
    _settings,
    _unenforced_solver,
    _validate_params,
    _write_period,
)
from mbh._adapters.exudyn_adapter.system import ExudynSystem
from mbh._harness.model.mechanism import PLANAR_JOINT_TYPES, Mechanism
from mbh._harness.common.status import CaseStatus
from mbh._harness.model.trajectory import BodyStates


@dataclass(frozen=True)
class ExudynModel:
    """What :meth:`ExudynAdapter.build` returns: the mechanism, checked for Exudyn.

    Each :meth:`ExudynAdapter.simulate` call builds a fresh Exudyn system from it, so one model
    serves any number of runs.

    Attributes
    ----------
    mechanism : Mechanism
    _unenforced_joints : bool
        Test-only hook: run Exudyn's explicit RK4 with ``eliminateConstraints=False``, the known
        trap in which Exudyn ignores every joint while reporting success.  Never offered as a method.
    """

    mechanism: Mechanism
    _unenforced_joints: bool = False


class ExudynAdapter(Adapter):
    """Exudyn (redundant absolute coordinates, implicit index-3/index-2 integrators)."""

    name = "exudyn"

    def version(self) -> str:
        return f"exudyn {exu.__version__}"

    def methods(self) -> list[MethodSpec]:
        return [
            MethodSpec("default", "Exudyn SolveDynamic defaults at fixed steps: generalized-alpha "
                       "(index 3), spectral radius 0.9, modified Newton", dict(_GENALPHA_PARAMS)),
            MethodSpec("newmark", "Newmark (useNewmark), index 3 unless index2=true; "
                       "gamma > 1/2 damps and is first order", dict(_NEWMARK_PARAMS)),
            MethodSpec("trapezoidal", "Exudyn TrapezoidalIndex2: undamped Newmark (beta=1/4, "
                       "gamma=1/2) with index-2 constraints", {**_NEWMARK_PARAMS, "index2": True}),
            MethodSpec("best", "most accurate measured without failing the hard scenes: "
                       "generalized-alpha (index 3), full Newton, tolerances 1e-12; joints held "
                       "to round-off at position level, velocity-level violation up to 1.3e-2 m/s "
                       "at dt 1e-3 (100x less per 10x smaller step); the index-2 trapezoidal rule "
                       "is 2-3x more accurate on smooth scenes but drifts in position and fails "
                       "Bricard at once", dict(_BEST)),
        ]

    def build(self, mechanism: Mechanism) -> ExudynModel:
        """Check that Exudyn can represent ``mechanism``.

        Raises
        ------
        UnsupportedCase
            A planar scenario with a joint type Exudyn has no 2D joint for.
        """
        if mechanism.planar:
            for joint in mechanism.joints:
                if joint.type not in PLANAR_JOINT_TYPES:
                    raise UnsupportedCase(f"planar joint {joint.name!r} of type {joint.type!r}: "
                                          f"Exudyn 2D joints are {', '.join(PLANAR_JOINT_TYPES)}")
        return ExudynModel(mechanism)

    def model_size(self, model: ExudynModel) -> dict:
        """ODE2 coordinates and algebraic equations (AE) of the Exudyn system a run builds
        (Euler-parameter nodes, the methods' default rotation; the AE include one normalisation
        per spatial node), and the redundant AE: rows minus the rank (``numpy.linalg.matrix_rank``)
        of Exudyn's own ∂AE/∂q at the start (``ComputeJacobianAE``, the ODE2 columns)."""
        coordinates, rows, rank = _algebraic_rank(model.mechanism, "ep")
        return {"coordinates": coordinates, "constraint_equations": rows,
                "redundant_equations": rows - rank,
                "notes": f"Exudyn ODE2 size {coordinates}, AE size {rows}, rank of ∂AE/∂q "
                         f"{rank}"}

    def bare_loop(self, model: ExudynModel, method: str, dt: float, n_steps: int) -> float:
        """Exudyn's own solve alone: ``n_steps`` fixed steps of ``method`` in one ``SolveSystem``
        call, with the settings :meth:`simulate` uses, on a system built (and assembled) off the
        clock without the body sensors :meth:`simulate` reads its samples from.

        Raises
        ------
        RunFailure
            When the solve fails (a failed run is no yardstick).
        """
        spec, params = self.method_spec(method)
        self._check_params(spec, params)
        with _quiet():
            system = ExudynSystem(model.mechanism, params["rotation"], sensors=False)
            settings = _settings(params, dt, n_steps, n_steps * dt)
            solver = _solver(model, settings)
            began = time.perf_counter()
            outcome = system.run(solver, settings, dt)
            seconds = time.perf_counter() - began
        if outcome.status != CaseStatus.OK:
            raise RunFailure(outcome.status, outcome.reason)
        return seconds

    def _check_params(self, spec: MethodSpec, params: dict) -> None:
        _validate_params(params)

    def _start(self, model: ExudynModel, spec: MethodSpec, params: dict,
               grid: RunGrid) -> "_ExudynStepper":
        return _ExudynStepper(model, spec.name, params, grid)


class _ExudynStepper(Stepper):
    """One Exudyn run at the fixed step ``dt``.

    Exudyn's ``SolveSystem`` takes every step in one call, so the first :meth:`_step_to` runs the
    whole solve; its sensors store the body states every :func:`_write_period` (a period that
    hits every sample and ``t_end``).  A failed solve ends the run when a later time is asked for,
    with the step before the failed one as the last good state; the samples before it are kept.
    """

    def __init__(self, model: ExudynModel, name: str, params: dict, grid: RunGrid):
        super().__init__()
        self.grid, self.mechanism, self.rotation = grid, model.mechanism, params["rotation"]
        self.notes = _notes(model.mechanism, name, params)
        n_steps = grid.steps(grid.t_end)
        indices = np.append(np.rint(grid.sample_times / grid.dt).astype(int), n_steps)
        with _quiet():
            self.system = ExudynSystem(model.mechanism, params["rotation"])
        self.settings = _settings(params, grid.dt, n_steps, _write_period(indices, grid.dt))
        self.solver = _solver(model, self.settings)
        self._outcome = None
        self._sensed = None

    def _step_to(self, t: float) -> None:
        if self._outcome is None:
            with _quiet():
                self._outcome = self.system.run(self.solver, self.settings, self.grid.dt)
            self.steps = self._outcome.steps
            self.t_good = self._outcome.t_good
        if self._outcome.status != CaseStatus.OK and self.grid.steps(t) > self._outcome.steps:
            raise RunFailure(self._outcome.status,
                             _singular_limit(self.mechanism, self.rotation) + self._outcome.reason)

    def _states(self, t: float) -> BodyStates:
        if self._sensed is None:
            self._sensed = self.system.sensed(self.grid.dt)
        states = self._sensed.get(self.grid.steps(t))
        if states is None:
            raise RunFailure(CaseStatus.FAILED, f"exudyn stored no sensor sample for t = {t:g} s")
        return states

    def counters(self) -> dict:
        return {} if self._outcome is None else dict(self._outcome.counters)


def _algebraic_rank(mechanism: Mechanism, rotation: str) -> tuple[int, int, int]:
    """ODE2 coordinates, algebraic equations (AE) and the rank (``numpy.linalg.matrix_rank``) of
    Exudyn's own ∂AE/∂q at the start (``ComputeJacobianAE``, the ODE2 columns) of the system a
    run with nodes ``rotation`` builds."""
    with _quiet():
        system = ExudynSystem(mechanism, rotation)
        solver = exu.MainSolverImplicitSecondOrder()
        settings = exu.SimulationSettings()
        settings.solution.file.write = False  # else solution/ appears in the working folder
        solver.InitializeSolver(system.mbs, settings)
        solver.ComputeJacobianAE(system.mbs, 1.0, 0.0, 0.0, False)
    coordinates, rows = int(solver.GetODE2size()), int(solver.GetAEsize())
    rank = int(np.linalg.matrix_rank(solver.GetSystemJacobian()[coordinates:, :coordinates]))
    return coordinates, rows, rank


def _singular_limit(mechanism: Mechanism, rotation: str) -> str:
    """The prefix of a failed run's reason naming the engine's limit on an overconstrained loop
    ('' on other mechanisms): with as many algebraic equations (AE) as coordinates or more, a
    mechanism that moves has at least AE − coordinates + 1 redundant ones, and Exudyn solves
    every step by Newton on a system Jacobian they make singular.  On spatial overconstrained
    loops (Bennett's 4R, Bricard's 6R) full Newton stops converging at some step,
    ``ignoreSingularJacobian`` or not (docs/measurements.md, "Engine settings on hard loops").
    The prefix gives the counts and the rank of Exudyn's own ∂AE/∂q at the start, as its system
    for the run's nodes builds them (on those two loops that rank is full: 21 of 21 coordinates,
    35 of 35, where the mechanism moves; the harness appends the mechanism's own count)."""
    coordinates, rows, rank = _algebraic_rank(mechanism, rotation)
    if rows < coordinates:
        return ""
    return (f"engine limit: Exudyn's Newton iteration on redundant equations ({rows} algebraic "
            f"equations on {coordinates} coordinates: at least {rows - coordinates + 1} "
            f"redundant for the mechanism to move; rank of Exudyn's ∂AE/∂q at the start "
            f"{rank}): ")


def _solver(model: ExudynModel, settings: exu.SimulationSettings):
    """Exudyn's implicit second-order solver (the test-only trap of :class:`ExudynModel` swaps in
    the explicit one and changes ``settings`` accordingly)."""
    if model._unenforced_joints:
        return _unenforced_solver(settings)
    return exu.MainSolverImplicitSecondOrder()


# ---------------------------------------------------------------------------------------------
# notes


#: The note naming the limit every run of an implicit method meets: its order.
ORDER_NOTE = ("engine limit: Exudyn's implicit integrators (generalized-α, Newmark) are second "
              "order, so the error falls as dt² (100× per 10× smaller step) where the fourth-order "
              "methods' falls as dt⁴ (docs/measurements.md, \"Engine settings on hard loops\")")


def _notes(mech: Mechanism, name: str, params: dict) -> list[str]:
    if mech.planar:
        return [f"exudyn {name}: planar model with NodeRigidBody2D "
                f"(parameter 'rotation' is not used)", ORDER_NOTE]
    node = "NodeRigidBodyEP" if params["rotation"] == "ep" else "NodeRigidBodyRotVecLG"
    return [f"exudyn {name}: spatial model with {node}", ORDER_NOTE]


@contextlib.contextmanager
def _quiet():
    """Keep Exudyn from printing to the console for the duration of a run."""
    previous = exu.config.printToConsole
    exu.config.printToConsole = False
    try:
        yield
    finally:
        exu.config.printToConsole = previous
