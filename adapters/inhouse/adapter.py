"""The in-house formulation behind the common adapter contract.

Method names are ``INTEGRATOR+STABILISATION[:key=value,...]`` (e.g. ``rk4+baumgarte``,
``bdf4+direct:tol=1e-5``, ``dop853+partition:rtol=1e-12``), plus ``ida[:...]`` (the DAE solver) and
the aliases ``default`` and ``best``.  Parameters go to whichever part declares them; the
integrator's and the strategy's parameter names are disjoint (``tol`` is always the integrator's
Newton tolerance, ``proj_tol`` the projection's, ``newton_tol`` the partitioning's).
"""

from __future__ import annotations

import itertools

import numpy as np

from adapters.base import Adapter, MethodSpec, parse_method
from adapters.inhouse import driver
from adapters.integrators import integrator_class, integrator_names, integrator_params
from adapters.inhouse.newton_euler import NewtonEuler
from adapters.inhouse.partition import CoordinatePartitioning
from adapters.inhouse.stabilisation import STRATEGIES
from harness.model import Mechanism
from harness.trajectory import Trajectory

FORMULATIONS = {**STRATEGIES, CoordinatePartitioning.name: CoordinatePartitioning,
                NewtonEuler.name: NewtonEuler}

#: What a user gets without choosing: the seed comparison's classic setting (α = β = 5).
DEFAULT_METHOD = "rk4+baumgarte"
#: The most accurate fixed-step setting: RK4 with position and velocity projection.
BEST_METHOD = "rk4+direct:proj_tol=1e-13"
ALIASES = {"default": DEFAULT_METHOD, "best": BEST_METHOD}


def _split(name: str) -> tuple[str, str]:
    integrator, plus, strategy = name.partition("+")
    if not plus:
        raise ValueError(f"in-house method {name!r} must be INTEGRATOR+STABILISATION "
                         f"(e.g. rk4+baumgarte), 'ida', 'default' or 'best'")
    if integrator not in integrator_names():
        raise ValueError(f"unknown integrator {integrator!r}; valid: {', '.join(integrator_names())}")
    if strategy not in FORMULATIONS:
        raise ValueError(f"unknown stabilisation {strategy!r}; valid: {', '.join(FORMULATIONS)}")
    return integrator, strategy


class InhouseAdapter(Adapter):
    """The project's own absolute-coordinate formulation (seeds 000 and 002)."""

    name = "inhouse"

    def version(self) -> str:
        from importlib.metadata import version
        return f"mbh-inhouse {version('mbh')}"

    def methods(self) -> list[MethodSpec]:
        specs = [MethodSpec("default", f"alias of {DEFAULT_METHOD}"),
                 MethodSpec("best", f"alias of {BEST_METHOD}")]
        for integrator, strategy in itertools.product(integrator_names(), FORMULATIONS):
            formulation = FORMULATIONS[strategy]
            specs.append(MethodSpec(
                f"{integrator}+{strategy}", formulation.description,
                {**integrator_params(integrator), **formulation.defaults}))
        from adapters.inhouse.dae import ida_params
        specs.append(MethodSpec("ida", "SUNDIALS IDA (scikit-sundae) on the DAE", ida_params()))
        return specs

    def method_spec(self, method: str) -> tuple[MethodSpec, dict]:
        name, given = parse_method(method)
        if name in ALIASES:
            if given:
                raise ValueError(f"the alias {name!r} takes no parameters; use {ALIASES[name]}")
            return self.method_spec(ALIASES[name])
        if name == "ida":
            from adapters.inhouse.dae import ida_params
            spec = MethodSpec("ida", "SUNDIALS IDA on the DAE", ida_params())
            return spec, spec.resolve(given)
        integrator, strategy = _split(name)
        spec = MethodSpec(name, FORMULATIONS[strategy].description,
                          {**integrator_params(integrator), **FORMULATIONS[strategy].defaults})
        return spec, spec.resolve(given)

    def build(self, mechanism: Mechanism) -> Mechanism:
        return mechanism

    def simulate(self, model: Mechanism, method: str, dt: float, t_end: float,
                 sample_times: np.ndarray) -> Trajectory:
        spec, params = self.method_spec(method)
        if spec.name == "ida":
            return _ida_trajectory(model, t_end, sample_times, params)
        integrator, strategy = _split(spec.name)
        formulation = FORMULATIONS[strategy]
        reason = formulation.unsupported_reason(model, integrator_class(integrator))
        if reason:
            return Trajectory.empty(len(model.bodies), status="unsupported", reason=reason)
        own = {k: v for k, v in params.items() if k in formulation.defaults}
        rest = {k: v for k, v in params.items() if k not in formulation.defaults}
        try:
            return driver.simulate(model, formulation, integrator, rest, own, dt, t_end, sample_times)
        except (ArithmeticError, np.linalg.LinAlgError, ValueError) as error:
            return Trajectory.empty(len(model.bodies), status="failed",
                                    reason=f"{type(error).__name__}: {error}", failure_time=0.0)


def _ida_trajectory(mech: Mechanism, t_end: float, sample_times, params: dict) -> Trajectory:
    """Run IDA from the assembled state and convert its samples to body states."""
    import time

    from adapters.inhouse.constraints import layout_of
    from adapters.inhouse.dae import simulate_ida
    from adapters.inhouse.kinematics import assemble
    from adapters.inhouse.states import trajectory_from_coordinates

    assembly = assemble(mech)
    began = time.perf_counter()
    result = simulate_ida(mech, assembly.q, assembly.v, t_end, sample_times, **params)
    wall = time.perf_counter() - began
    counters = {k: v for k, v in result.counters.items() if k != "steps" and v is not None}
    return trajectory_from_coordinates(
        layout_of(mech), result.times, result.q, result.v, status=result.status,
        reason=result.reason or "", failure_time=result.failure_time, wall_time_s=wall,
        steps=result.counters.get("steps", 0), counters=counters)
