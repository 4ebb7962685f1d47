"""The Pinocchio adapter: the harness's contract over :mod:`.build`, :mod:`.state` and
:mod:`.dynamics`.

Pinocchio computes constrained accelerations but has no time integrator; the harness's own
integrators (:mod:`adapters.integrators`) drive it, the configuration integrated on its
manifold by ``pin.integrate``.  A method is an integrator × constraint-solver settings (Baumgarte
gains, proximal ``mu``, ``max_iter``, ``accuracy``) × projection on/off; every method takes every
parameter, only the defaults differ.
"""

from __future__ import annotations

import time

import numpy as np
import pinocchio as pin

from adapters.base import Adapter, MethodSpec
from adapters.integrators import RUNNING, integrator_names, make_integrator
from adapters.pinocchio_adapter.build import PinocchioModel, build_model
from adapters.pinocchio_adapter.dynamics import ConstrainedProblem, SolverSettings
from adapters.pinocchio_adapter.state import body_states, joint_state
from harness.initial import initial_state
from harness.model import Mechanism
from harness.trajectory import BodyStates, Trajectory

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

    def simulate(self, model: PinocchioModel, method: str, dt: float, t_end: float,
                 sample_times: np.ndarray) -> Trajectory:
        """Integrate from the harness's assembled state and sample every body.

        Parameters
        ----------
        model : PinocchioModel
            From :meth:`build`.
        method : str
            ``NAME[:key=value,...]``; see :meth:`methods`.
        dt, t_end : float
            Step and end time, s; ``round(t_end / dt)`` steps are taken.
        sample_times : ndarray, shape (n_samples,)
            Integer multiples of ``dt`` (0 included); the state after step ``round(t / dt)`` is
            recorded.

        Returns
        -------
        Trajectory
            ``failed`` with the reason when Pinocchio returns NaN or the projection or the start
            conversion fails, ``diverged`` when the state blows up; the samples before it.

        Raises
        ------
        ValueError
            For an unknown method, parameter or integrator name.
        """
        _, params = self.method_spec(method)
        if params["integrator"] not in integrator_names():
            raise ValueError(f"unknown integrator {params['integrator']!r}; valid: "
                             f"{', '.join(integrator_names())}")
        settings = solver_settings(params)
        n_bodies = len(model.mechanism.bodies)
        notes = list(model.notes)
        problem = ConstrainedProblem(model, settings)
        try:
            start = initial_state(model.mechanism)
            q0, v0 = joint_state(model, problem.kin_data, start)
        except ValueError as exc:
            return Trajectory.empty(n_bodies, status="failed", failure_time=0.0, notes=notes,
                                    reason=f"no joint-coordinate start: {exc}")
        try:
            integrator = make_integrator(params["integrator"], problem, 0.0, q0, v0, dt)
        except ValueError as exc:
            return Trajectory.empty(n_bodies, status="unsupported", reason=str(exc), notes=notes)
        return _run(model, problem, integrator, start, dt, t_end, np.asarray(sample_times),
                    notes)

def _run(pm: PinocchioModel, problem: ConstrainedProblem, integrator, start: BodyStates,
         dt: float, t_end: float, sample_times: np.ndarray, notes: list) -> Trajectory:
    """Step ``integrator`` to ``t_end``, recording the samples; wall time of the stepping only.

    ``start`` (the harness's initial state) fixes the sign of the first sampled quaternions.
    """
    n_steps = int(round(t_end / dt))
    sample_steps = np.rint(np.asarray(sample_times) / dt).astype(int)
    data = pm.model.createData()
    states = []
    previous = start.quaternion
    wall = 0.0
    for index, target in enumerate(sample_steps):
        start = time.perf_counter()
        while integrator.n_steps < min(target, n_steps) and integrator.step() == RUNNING:
            pass
        wall += time.perf_counter() - start
        if integrator.status != RUNNING or target > n_steps:
            break
        states.append(body_states(pm, data, integrator.q, integrator.v, previous))
        previous = states[-1].quaternion
    status = "ok" if integrator.status == RUNNING else integrator.status
    counters = {"rhs_evals": integrator.nfev, "factorizations": integrator.nfev,
                **problem.counters}
    return Trajectory.from_samples(sample_times, states, status=status,
                                   reason=integrator.failure_reason or "",
                                   failure_time=integrator.failure_time, wall_time_s=wall,
                                   steps=integrator.n_steps, counters=counters, notes=notes)
