"""The in-house stepper on the compiled path (:mod:`adapters.inhouse.compiled`): from one sample
time to the next in a single compiled call, so no Python runs per step.

Used for the fixed-step explicit one-step methods (euler, symplectic-euler, heun, rk4, rkn4) with
the ``none``, ``baumgarte`` and ``direct`` formulations unless the method says ``loop=python``;
every other method runs on :class:`~adapters.inhouse.driver.InhouseStepper`.  The formulation
object is built as on the Python path (its rows, gains, projection cut and notes are the
compiled loop's inputs), so both paths integrate the same equations with the same arithmetic.
"""

from __future__ import annotations

import numpy as np

from adapters.base import RunFailure, RunGrid, Stepper
from adapters.inhouse import compiled
from adapters.inhouse.constraints import layout_of
from adapters.inhouse.kinematics import common_start
from adapters.inhouse.stabilisation import Baumgarte, DirectCorrection, NoStabilisation
from adapters.inhouse.states import body_states
from adapters.integrators import integrator_class
from adapters.integrators.nystrom import NystromIntegrator
from harness.model import Mechanism
from harness.trajectory import BodyStates

#: Formulations with a compiled path and their stabilisation code in :func:`compiled.run_steps`.
COMPILED_FORMULATIONS = {NoStabilisation.name: compiled.PLAIN, Baumgarte.name: compiled.PLAIN,
                         DirectCorrection.name: compiled.PROJECTED}

#: The ``loop`` method parameter: which stepping path runs a method that has both.
LOOPS = ("compiled", "python")

_FAILURES = {compiled.DIVERGED_NONFINITE: ("diverged", "non-finite state"),
             compiled.FAILED_LINALG: ("failed", "LinAlgError: a factorisation failed in the "
                                                "compiled step")}


def has_compiled_path(integrator_name: str, formulation_name: str) -> bool:
    """True when ``integrator+formulation`` can run on the compiled path."""
    return (formulation_name in COMPILED_FORMULATIONS
            and issubclass(integrator_class(integrator_name), NystromIntegrator))


class CompiledStepper(Stepper):
    """One fixed-step run of ``formulation_class`` by the Nyström tableau of ``integrator_name``.

    Parameters
    ----------
    mech : Mechanism
    formulation_class : type
        One of :data:`COMPILED_FORMULATIONS`' classes.
    integrator_name : str
        A :class:`~adapters.integrators.nystrom.NystromIntegrator` method.
    integrator_params, formulation_params : dict
        Resolved parameters of each part (``divergence_limit`` is the integrator's).
    grid : RunGrid
    """

    def __init__(self, mech: Mechanism, formulation_class, integrator_name: str,
                 integrator_params: dict, formulation_params: dict, grid: RunGrid):
        super().__init__()
        self.grid = grid
        self.layout = layout_of(mech)
        assembly = common_start(mech)
        self.q, self.v = assembly.q.copy(), assembly.v.copy()
        formulation = formulation_class(mech, assembly.q, grid.dt, **formulation_params)
        self.formulation = formulation
        self.notes = list(formulation.notes)
        tableau = integrator_class(integrator_name).tableau
        projected = COMPILED_FORMULATIONS[formulation_class.name] == compiled.PROJECTED
        self._limit = float(integrator_params["divergence_limit"])
        self._counters = np.zeros(4, dtype=np.int64)
        self._arguments = (
            (tableau.c, tableau.a, tableau.abar, tableau.b, tableau.bbar),
            np.asarray(formulation.gains, dtype=float),
            COMPILED_FORMULATIONS[formulation_class.name],
            float(formulation.params["proj_tol"]) if projected else 0.0,
            int(formulation.params["proj_max_iter"]) if projected else 0,
            float(formulation.cut) if projected else 0.0,
            self._limit, np.ascontiguousarray(formulation.rows),
            formulation.constraints.kernel_args, formulation.dynamics.kernel_args,
            formulation.constraints.sparsity.arrays)
        self._run(0)  # compile (or load from numba's cache) outside the timed stepping

    def _run(self, last: int):
        return compiled.run_steps(self.q, self.v, 0.0, self.grid.dt, self.steps, last,
                                  *self._arguments, self._counters)

    def _step_to(self, t: float) -> None:
        self.q, self.v, self.steps, status = self._run(self.grid.steps(t))
        self.t_good = self.steps * self.grid.dt
        if status == compiled.DIVERGED_LIMIT:
            raise RunFailure("diverged", f"state norm exceeds divergence_limit={self._limit:g}")
        if status != compiled.RUNNING:
            raise RunFailure(*_FAILURES[status])

    def _states(self, t: float) -> BodyStates:
        return body_states(self.layout, self.q, self.v)

    def counters(self) -> dict:
        own = self.formulation.counters
        return {"rhs_evals": int(self._counters[compiled.RHS_EVALS]),
                "jacobian_evals": own["jacobian_evals"]
                + int(self._counters[compiled.JACOBIAN_EVALS]),
                "factorizations": own["factorizations"]
                + int(self._counters[compiled.FACTORIZATIONS]),
                "newton_iterations": own["newton_iterations"]
                + int(self._counters[compiled.NEWTON_ITERATIONS]),
                "repartitions": 0}
