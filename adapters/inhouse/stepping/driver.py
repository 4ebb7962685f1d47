"""The in-house stepper: a formulation (stabilisation strategy) integrated by one method from the
assembled initial state, driven by the shared run loop (:meth:`mbh._adapters.base.Adapter.simulate`).

Fixed-step methods are read after step round(t / dt).  Adaptive methods are read at the sample
times: the state of the step that ends there, else the solver's dense output inside the last
step.  Dense output is not a state the method carried when the formulation corrects the state
after every step (``direct``, ``geometric``): it is then projected at each sample
time (:meth:`InhouseStepper._carried`: the position projection of Rouvinen 2003, eq. 127 and the
velocity projection of eq. 137, the ``direct`` strategy's correction), so that the reported
constraint violations and energies are those of states on the manifold the method keeps its steps
on.  That projection is a reading, not part of the method: its cost is not counted, and the
integration goes on from the step's own state.
"""

from __future__ import annotations

import numpy as np

from mbh._adapters.base import RunFailure, RunGrid, Stepper
from mbh._harness.common.kernel_cache import first_use
from mbh._adapters.inhouse.bodies.constraints import layout_of
from mbh._adapters.inhouse.formulations.fold import Passages
from mbh._adapters.inhouse.bodies.kinematics import common_start
from mbh._adapters.inhouse.formulations.stabilisation import Formulation
from mbh._adapters.inhouse.bodies.states import body_states
from mbh._adapters.integrators import IntegratorState, make_integrator
from mbh._harness.model.mechanism import Mechanism
from mbh._harness.model.trajectory import BodyStates

#: Measured first compilation of what the start and a formulation's construction call, s
#: (2-core machine, 2026-11-29, with Φ, Φ_q and γ compiled alone without their helpers inlined:
#: 14 s in all; Φ 1.7, Φ_q 1.8, γ 2.3, the rank's full pivoting 4.3, ρ̂ 3.5).
START_COMPILE_S = 15.0
#: Measured first compilation of what a formulation's ``warm_up`` calls on the Python loop, s
#: (2-core machine, 2026-11-29, empty cache): the absolute kernels' right-hand side ~80 s, the
#: joint-coordinate one with its solves ~70 s.  Keyed by the formulation's class, as the start's
#: block above: the absolute and joint-coordinate ``direct`` compile different kernels.
RIGHT_HAND_SIDE_COMPILE_S = 75.0
_INTEGRATOR_COUNTERS = {"rhs_evals": "nfev", "jacobian_evals": "njev", "factorizations": "nlu",
                        "newton_iterations": "n_newton"}

#: Note of an adaptive run whose dense-output samples are projected.
PROJECTED_SAMPLES_NOTE = ("adaptive steps with projection: states between steps (dense output) "
                          "are projected onto the constraints at each sample time (positions "
                          "Rouvinen 2003, eq. 127, velocities eq. 137); the projection is not counted")


class FormulationStepper(Stepper):
    """What the in-house steppers share: the body layout, the common start
    (:func:`~mbh._adapters.inhouse.bodies.kinematics.common_start`) and the formulation built there.

    Parameters
    ----------
    mech : Mechanism
    formulation_class : type[Formulation]
    formulation_params : dict
        Resolved parameters of the formulation.
    grid : RunGrid
    """

    def __init__(self, mech: Mechanism, formulation_class, formulation_params: dict,
                 grid: RunGrid):
        super().__init__()
        self.grid = grid
        self.layout = layout_of(mech)
        # Per formulation: each calls its own kernels at its construction (ρ̂ only some).
        with first_use(f"start-{formulation_class.__name__}",
                                 "the kernels of the start and of the formulations "
                                 "(Φ, Φ_q, γ, the rank, ρ̂)", START_COMPILE_S):
            assembly = common_start(mech)
            self._start_state = (assembly.q, assembly.v)
            self.formulation: Formulation = formulation_class(mech, assembly.q, grid.dt,
                                                              **formulation_params)
        self.notes = list(self.formulation.notes)


class InhouseStepper(FormulationStepper):
    """One run of ``formulation_class`` integrated by ``integrator_name``.

    Parameters
    ----------
    mech : Mechanism
    formulation_class : type[Formulation]
    integrator_name : str
        A name from :func:`mbh._adapters.integrators.integrator_names`.
    integrator_params, formulation_params : dict
        Resolved parameters of each part.
    grid : RunGrid
        ``dt`` is the fixed step, or the first-step hint of an adaptive method.

    Attributes
    ----------
    formulation : Formulation
    integrator : Integrator
        The current one (coordinate partitioning restarts it at every re-partition).
    """

    def __init__(self, mech: Mechanism, formulation_class, integrator_name: str,
                 integrator_params: dict, formulation_params: dict, grid: RunGrid):
        super().__init__(mech, formulation_class, formulation_params, grid)
        formulation, (q0, v0) = self.formulation, self._start_state
        formulation.start(q0, v0)
        with first_use(f"warm-up-{formulation_class.__name__}",
                                 "the formulation's right-hand side and projection",
                                 RIGHT_HAND_SIDE_COMPILE_S):
            formulation.warm_up(q0, v0)
        self.integrator_name, self.integrator_params = integrator_name, integrator_params
        self._spent = dict.fromkeys(_INTEGRATOR_COUNTERS, 0)
        self._banked_steps = 0
        self.integrator = None
        self._restart(0.0, q0, v0)
        self._adaptive = self.integrator.adaptive
        self._project_samples = self._adaptive and formulation.corrects
        if self._project_samples:
            self.notes.append(PROJECTED_SAMPLES_NOTE)
        self._repartition_due = False
        self.passages = Passages.of(formulation, self.integrator)

    # -- stepping ------------------------------------------------------------------------------
    def _step_to(self, t: float) -> None:
        if self._adaptive:
            while self.integrator.t < t:
                self._step()
        else:
            last = self.grid.steps(t)
            while self.steps < last:
                self._step(last)

    def _step(self, last: int = 0) -> None:
        """One integrator step, or a placed passage of a singular position ending by grid step
        ``last`` (fixed-step methods); the re-partition check of the previous step's state
        first."""
        if self._repartition_due:
            self._repartition_if_needed()
        integrator = self.integrator
        passage = self.passages.plan(self.steps, self.grid.dt, last)
        if passage is None:
            status = integrator.step()
        else:
            status = integrator.step_through(*passage)
            self.passages.count[0] += status == IntegratorState.RUNNING
        self.steps = self._banked_steps + integrator.n_steps
        self.t_good = integrator.t
        if status != IntegratorState.RUNNING:
            raise RunFailure(status, integrator.failure_reason or status)
        self._repartition_due = True

    def _restart(self, t: float, q_full: np.ndarray, v_full: np.ndarray) -> None:
        """(Re)start the integrator from a full state, keeping the cost of the previous one."""
        if self.integrator is not None:
            for key, attribute in _INTEGRATOR_COUNTERS.items():
                self._spent[key] += getattr(self.integrator, attribute)
            self._banked_steps += self.integrator.n_steps
        q, v = self.formulation.reduce(q_full, v_full)
        self.integrator = make_integrator(self.integrator_name, self.formulation, t, q, v,
                                          self.grid.dt, **self.integrator_params)

    def _repartition_if_needed(self) -> None:
        """Choose the integrated coordinates again when the formulation asks (partitioning)."""
        self._repartition_due = False
        integrator = self.integrator
        q, v = self.formulation.expand(integrator.t, integrator.q, integrator.v)
        if self.formulation.needs_repartition(q):
            self.formulation.choose_partition(q)
            self._restart(integrator.t, q, v)

    # -- reading -------------------------------------------------------------------------------
    def _states(self, t: float) -> BodyStates:
        return body_states(self.layout, *self._coordinates(t))

    def _coordinates(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Full (q, q̇) at ``t``: the start, the current step's state, or projected dense output."""
        integrator = self.integrator
        if self.steps == 0:
            return self._start_state
        if not self._adaptive or t == integrator.t:
            return self.formulation.expand(integrator.t, integrator.q, integrator.v)
        q, v = self.formulation.expand(t, *integrator.dense(t))
        return self._carried(t, q, v) if self._project_samples else (q, v)

    def _carried(self, t: float, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(q, q̇) at ``t`` put back on the constraints; the formulation's counters are left as
        they were.

        The position projection (Rouvinen 2003, eq. 127) of the formulation (``direct``, ``geometric``: the
        only correcting ones), then the velocity projection q̇ − Φ_q⁺ Φ_q q̇ (eq. 137,
        minimum-norm least squares): ``geometric``'s own velocity correction integrates the work
        along the steps and cannot be replayed at a sample.
        """
        formulation = self.formulation
        counters = dict(formulation.counters)
        q = formulation.project_position(t, q)
        jac = formulation.jacobian(t, q)
        v = v - np.linalg.lstsq(jac, jac @ v, rcond=None)[0]
        formulation.counters.update(counters)
        return q, v

    def counters(self) -> dict:
        counters = {key: self._spent[key] + getattr(self.integrator, attribute)
                    + self.formulation.counters.get(key, 0)
                    for key, attribute in _INTEGRATOR_COUNTERS.items()}
        counters["repartitions"] = getattr(self.formulation, "repartitions", 0)
        counters["passages"] = int(self.passages.count[0])
        return counters
