"""The Pinocchio adapter: the harness's contract over :mod:`.build`, :mod:`.state` and
:mod:`.dynamics`.

Pinocchio computes constrained accelerations but has no time integrator; the harness's own
integrators (:mod:`mbh._adapters.integrators`) drive it, the configuration integrated on its
manifold by ``pin.integrate``.  A method is an integrator × constraint-solver settings (Baumgarte
gains, proximal ``mu``, ``max_iter``, ``accuracy``) × projection on/off; every method takes every
parameter, only the defaults differ.
"""

from __future__ import annotations

import time

import pinocchio as pin

from mbh._adapters.base import Adapter, MethodSpec, RunFailure, RunGrid, Stepper, UnsupportedCase
from mbh._adapters.integrators import IntegratorState, integrator_names, make_integrator
from mbh._adapters.integrators.nystrom import NystromIntegrator, step_rule
from mbh._adapters.pinocchio_adapter.build import PinocchioModel, build_model
from mbh._adapters.pinocchio_adapter.dynamics import (
    SolverSettings,
    proximal_notes,
    redundancy_notes,
)
from mbh._adapters.pinocchio_adapter.state import body_states, joint_state
from mbh._adapters.pinocchio_adapter.stepping import bare_rule, bare_steps, constrained_problem
from mbh._harness.neutral.start import initial_state
from mbh._harness.model.mechanism import Mechanism
from mbh._harness.model.trajectory import BodyStates, Trajectory

_PIN_DEFAULTS = pin.ProximalSettings()
#: Parameters every method takes, at Pinocchio's own defaults (``ProximalSettings()`` as
#: constructed, zero corrector gains) and the naive user's integrator.
_DEFAULT_PARAMS = {
    "integrator": "symplectic-euler",
    "kp": 0.0,
    "kd": 0.0,
    "mu": float(_PIN_DEFAULTS.mu),
    "max_iter": int(_PIN_DEFAULTS.max_iter),
    "accuracy": float(_PIN_DEFAULTS.absolute_accuracy),
    "project": False,
    "project_tol": 1e-12,
    "project_max_iter": 10,
}
#: Proximal settings that converge with redundant closure rows (mu > 0, several iterations).
_GOOD_PROX = {"mu": 1e-8, "max_iter": 20, "accuracy": 1e-12}


def _spec(name: str, description: str, **overrides) -> MethodSpec:
    """A method taking every parameter, with ``overrides`` replacing the default values."""
    return MethodSpec(name, description, {**_DEFAULT_PARAMS, **overrides})


_METHODS = (
    _spec("default", "Pinocchio's defaults as a naive user gets them: ProximalSettings() "
          "(mu = 0, one iteration), no Baumgarte correction, symplectic Euler, no projection"),
    _spec("best", "RK4 with converged proximal solves and position + velocity projection onto "
          "the loop-closure manifold after every step", integrator="rk4", project=True,
          **_GOOD_PROX),
    _spec("rk4", "RK4 with converged proximal solves, no stabilisation (the loop drifts)",
          integrator="rk4", **_GOOD_PROX),
    _spec("baumgarte", "RK4 with Pinocchio's Baumgarte corrector at Rouvinen's alpha = beta = 5 "
          "(Kp = beta² = 25, Kd = 2 alpha = 10)", integrator="rk4", kp=25.0, kd=10.0,
          **_GOOD_PROX),
    _spec("symplectic-projected", "Symplectic Euler with converged proximal solves and "
          "projection after every step", project=True, **_GOOD_PROX),
)


def solver_settings(params: dict) -> SolverSettings:
    """The constraint-solver part of resolved method parameters."""
    return SolverSettings(**{key: params[key] for key in (
        "kp", "kd", "mu", "max_iter", "accuracy", "project", "project_tol", "project_max_iter")})


class PinocchioAdapter(Adapter):
    """Pinocchio (``pin``): tree dynamics in joint coordinates with rigid loop constraints."""

    name = "pinocchio"

    def version(self) -> str:
        return f"pinocchio {pin.__version__}"

    def methods(self) -> list[MethodSpec]:
        return list(_METHODS)

    def build(self, mechanism: Mechanism) -> PinocchioModel:
        """The Pinocchio model of ``mechanism`` (see :func:`.build.build_model`)."""
        return build_model(mechanism)

    def model_size(self, model: PinocchioModel) -> dict:
        """``nq`` of the kinematic tree and the rows of its loop-closure constraints
        (``RigidConstraintModel.residualSize()``: 3 for a point contact, 6 for a 6-D one);
        redundant rows are the closure equations beyond the cut joints' class in the mechanism's
        dimension."""
        rows = sum(int(constraint.residualSize()) for constraint in model.constraints)
        return {"coordinates": int(model.model.nq), "constraint_equations": rows,
                "redundant_equations": model.tree.redundant_closure_equations,
                "notes": f"Pinocchio nq = {model.model.nq} (tree joints), "
                         f"{len(model.constraints)} rigid constraint(s) with {rows} rows closing "
                         f"the loops"}

    def bare_loop(self, model: PinocchioModel, method: str, dt: float, n_steps: int) -> float:
        """The plain loop alone (:func:`.stepping.bare_steps`): ``n_steps`` steps of the method's
        explicit one-step integrator calling ``pin.constraintDynamics`` and ``pin.integrate``,
        with the method's projection, from the start :meth:`simulate` uses; no samples, no
        counters, no checks.  The start's conversion to joint coordinates is off the clock.

        Raises
        ------
        UnsupportedCase
            For an integrator that is not an explicit one-step method.
        """
        spec, params = self.method_spec(method)
        self._check_params(spec, params)
        problem = constrained_problem(model, solver_settings(params))
        q, v = joint_state(model, problem.kin_data, initial_state(model.mechanism))
        rule = bare_rule(problem, params["integrator"])
        began = time.perf_counter()
        bare_steps(problem, rule, q, v, dt, n_steps)
        return time.perf_counter() - began

    def _check_params(self, spec: MethodSpec, params: dict) -> None:
        if params["integrator"] not in integrator_names():
            raise ValueError(f"unknown integrator {params['integrator']!r}; valid: "
                             f"{', '.join(integrator_names())}")

    def _start(self, model: PinocchioModel, spec: MethodSpec, params: dict,
               grid: RunGrid) -> "_PinocchioStepper":
        return _PinocchioStepper(model, params, grid)


class _PinocchioStepper(Stepper):
    """One integrator of :mod:`mbh._adapters.integrators` driving Pinocchio's constrained dynamics
    from the harness's assembled start, converted to joint coordinates.

    Samples are read after step ``round(t / dt)``.  The integrator's own check (non-finite or
    norm above its ``divergence_limit``) and its failures (NaN from Pinocchio, a projection that
    does not converge) end the run at its last good state.  A start no joint state reproduces
    raises (``failed`` at t = 0); an integrator that cannot run on Pinocchio's configuration
    space is ``unsupported``.
    """

    def __init__(self, model: PinocchioModel, params: dict, grid: RunGrid):
        super().__init__()
        self.pm, self.grid = model, grid
        self.problem = constrained_problem(model, solver_settings(params))
        start = initial_state(model.mechanism)
        q0, v0 = joint_state(model, self.problem.kin_data, start)
        self.notes = redundancy_notes(self.problem, q0)
        try:
            self.integrator = make_integrator(params["integrator"], self.problem, 0.0, q0, v0,
                                              grid.dt)
        except ValueError as exc:
            raise UnsupportedCase(str(exc)) from None
        self.data = model.model.createData()
        self._previous = start.quaternion  # fixes the sign of the first sampled quaternions
        # Explicit one-step methods step unchecked between samples and check the state once per
        # sample, replaying the sample's steps checked when it fails (the per-call NaN test and
        # the integrator's bookkeeping cost ~9 µs a step, a fifth of the step); other methods
        # step checked.
        self._unchecked_rule = (
            step_rule(type(self.integrator), self.problem, self.problem.counted_acceleration)
            if isinstance(self.integrator, NystromIntegrator) else None)

    def run(self, grid: RunGrid, n_bodies: int) -> Trajectory:
        """The shared run loop, then the note on unconverged proximal solves
        (:func:`.dynamics.proximal_notes`), which only the whole run can count."""
        trajectory = super().run(grid, n_bodies)
        trajectory.notes.extend(proximal_notes(self.problem))
        return trajectory

    def _step_to(self, t: float) -> None:
        integrator, target = self.integrator, self.grid.steps(t)
        if self._unchecked_rule is not None:
            try:
                status = integrator.steps_unchecked(target - integrator.n_steps,
                                                    self._unchecked_rule)
            finally:  # an engine error raised through keeps the last good step
                self.steps, self.t_good = integrator.n_steps, integrator.t
            if status != IntegratorState.RUNNING:
                raise RunFailure(status, integrator.failure_reason or status)
            return
        while integrator.n_steps < target:
            status = integrator.step()
            self.steps, self.t_good = integrator.n_steps, integrator.t
            if status != IntegratorState.RUNNING:
                raise RunFailure(status, integrator.failure_reason or status)

    def _states(self, t: float) -> BodyStates:
        states = body_states(self.pm, self.data, self.integrator.q, self.integrator.v,
                             self._previous)
        self._previous = states.quaternion
        return states

    def counters(self) -> dict:
        return {"rhs_evals": self.integrator.nfev, "factorizations": self.integrator.nfev,
                **self.problem.counters}
