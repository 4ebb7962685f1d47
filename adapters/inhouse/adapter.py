"""The in-house formulation behind the common adapter contract.

Method names are ``INTEGRATOR+STABILISATION[:key=value,...]`` (e.g. ``rk4+baumgarte``,
``bdf4+direct:tol=1e-5``, ``dop853+partition:rtol=1e-12``), plus ``ida[:...]`` (the DAE solver) and
the aliases ``default`` and ``best`` (which take ``coords`` alone: ``best:coords=joint`` is
``rk4+direct:proj_tol=1e-15,coords=joint``).  Parameters go to whichever part declares them; the
integrator's and the strategy's parameter names are disjoint (``tol`` is always the integrator's
Newton tolerance, ``proj_tol`` the projection's, ``newton_tol`` the partitioning's).  Explicit
one-step methods with ``none``, ``baumgarte``, ``direct`` or ``partition``, and linear multistep
methods with ``none``, ``baumgarte`` or ``direct``, run compiled, with functions generated for
the mechanism (``loop=auto``, the default, or ``generated``;
:mod:`mbh._adapters.inhouse.stepping.compiled_stepper`), with the generic kernels (``loop=compiled``) or
stepped from Python (``loop=python``); all compute the same numbers (the implicit multistep
methods to their Newton tolerance: :mod:`mbh._adapters.inhouse.stepping.compiled_multistep`).
``none``, ``baumgarte``, ``direct`` and ``partition`` also take ``coords=joint``: the same
treatment in the spanning tree's joint coordinates
(:mod:`mbh._adapters.inhouse.formulations.joint_coordinates`,
:mod:`mbh._adapters.inhouse.formulations.joint_partition`), on their compiled loop where it runs the
method (the explicit one-step methods and ab1–ab5 with ``none``, ``baumgarte`` or ``direct``:
:mod:`mbh._adapters.inhouse.stepping.joint_loop`; ``loop=auto`` or ``compiled``), else, and with
``loop=python``, on the Python loop.
"""

from __future__ import annotations

import functools
import itertools
import time

import numpy as np

from mbh._adapters.base import Adapter, MethodSpec, RunGrid, Stepper, UnsupportedCase, parse_method
from mbh._adapters.inhouse.stepping.compiled_stepper import (
    LOOPS, CompiledStepper, has_compiled_path)
from mbh._adapters.inhouse.stepping.driver import InhouseStepper
from mbh._adapters.inhouse.stepping.joint_loop import (JointLoopStepper, joint_loop,
                                                       joint_loop_unsupported)
from mbh._adapters.inhouse.stepping.joint_stepper import JointStepper
from mbh._adapters.integrators import integrator_class, integrator_names, integrator_params
from mbh._adapters.inhouse.formulations.joint_coordinates import (COORDINATES, JOINT_LOOPS,
                                                                  JOINT_TREATMENTS,
                                                                  auto_coordinates,
                                                                  joint_model_size)
from mbh._adapters.inhouse.formulations.joint_partition import JointPartition
from mbh._adapters.inhouse.formulations.newton_euler import NewtonEuler
from mbh._adapters.inhouse.formulations.partition import CoordinatePartitioning
from mbh._adapters.inhouse.formulations.stabilisation import STRATEGIES
from mbh._harness.model.mechanism import Mechanism
from mbh._harness.model.trajectory import BodyStates

FORMULATIONS = {**STRATEGIES, CoordinatePartitioning.name: CoordinatePartitioning,
                NewtonEuler.name: NewtonEuler}
#: The treatments that also run in joint coordinates (``coords=joint``), by name.
JOINT_FORMULATIONS = {**JOINT_TREATMENTS, JointPartition.name: JointPartition}

#: What a user gets without choosing: the seed comparison's classic setting (α = β = 5).
DEFAULT_METHOD = "rk4+baumgarte"
#: The most accurate fixed-step setting: RK4 with position and velocity projection, Newton to
#: round-off (near a singular position a residual ε leaves the state ~ε/ψ off the branch, see
#: :class:`~mbh._adapters.inhouse.formulations.stabilisation.DirectCorrection`), singular positions passed by placed
#: steps (:mod:`mbh._adapters.inhouse.formulations.fold`).
BEST_METHOD = "rk4+direct:proj_tol=1e-15"
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


def _spec(integrator: str, strategy: str) -> MethodSpec:
    """The method ``integrator+strategy`` with the parameters of both parts; methods with a
    compiled path add ``loop`` (:data:`~mbh._adapters.inhouse.stepping.compiled_stepper.LOOPS`: ``auto``, the
    default, ``generated``, ``compiled`` or ``python``), treatments that also run in joint
    coordinates add ``coords`` (:data:`~mbh._adapters.inhouse.formulations.joint_coordinates.
    COORDINATES`: ``absolute``, the default, ``joint`` or ``auto``)."""
    formulation = FORMULATIONS[strategy]
    params = {**integrator_params(integrator), **formulation.defaults}
    description = formulation.description
    if has_compiled_path(integrator, strategy):
        params["loop"] = LOOPS[0]
    if strategy in JOINT_FORMULATIONS:
        params["coords"] = COORDINATES[0]
        description += ("; coords=joint: in the spanning tree's joint coordinates (their "
                        "compiled loop where it runs the method, else Python), coords=auto: the "
                        "smaller model")
    return MethodSpec(f"{integrator}+{strategy}", description, params)


@functools.cache
def _mbh_version() -> str:
    """The installed mbh's version, read once per process (~2 ms from the package metadata, asked
    twice by every case; a campaign's cases find the warm template's)."""
    from importlib.metadata import version

    return version("mbh")


class InhouseAdapter(Adapter):
    """The project's own absolute-coordinate formulation (Frączek & Wojtyra 2009; Rouvinen 2003)."""

    name = "inhouse"

    def version(self) -> str:
        return f"mbh-inhouse {_mbh_version()}"

    def methods(self) -> list[MethodSpec]:
        in_joint = "; takes coords (joint, auto) alone"
        specs = [MethodSpec("default", f"alias of {DEFAULT_METHOD}{in_joint}"),
                 MethodSpec("best", f"alias of {BEST_METHOD}{in_joint}")]
        for integrator, strategy in itertools.product(integrator_names(), FORMULATIONS):
            specs.append(_spec(integrator, strategy))
        from mbh._adapters.inhouse.formulations.dae import ida_params
        specs.append(MethodSpec("ida", "SUNDIALS IDA (scikit-sundae) on the DAE", ida_params()))
        return specs

    def method_spec(self, method: str) -> tuple[MethodSpec, dict]:
        name, given = parse_method(method)
        if name in ALIASES:
            others = sorted(set(given) - {"coords"})
            if others:
                raise ValueError(f"the alias {name!r} takes coords only (its method in the chosen "
                                 f"coordinates), not {', '.join(others)}; use {ALIASES[name]}")
            method = ALIASES[name]
            if given:
                method += ("," if ":" in method else ":") + f"coords={given['coords']}"
            return self.method_spec(method)
        if name == "ida":
            from mbh._adapters.inhouse.formulations.dae import ida_params
            spec = MethodSpec("ida", "SUNDIALS IDA on the DAE", ida_params())
            return spec, spec.resolve(given)
        spec = _spec(*_split(name))
        return spec, spec.resolve(given)

    def build(self, mechanism: Mechanism) -> Mechanism:
        return mechanism

    def model_size(self, model: Mechanism) -> dict:
        """Absolute coordinates q (3 per planar body; 7 per spatial body: position and Euler
        parameters) and the Φ rows of the joints (with the Euler-parameter normalisations), the
        redundant ones from the rank analysis at the common start
        (:func:`.kinematics.rank_report`, full-pivot elimination of Φ_q)."""
        from mbh._adapters.inhouse.bodies.kinematics import common_start, rank_report

        report = rank_report(model, common_start(model).q)
        return {"coordinates": report.n_coordinates, "constraint_equations": report.n_equations,
                "redundant_equations": len(report.redundant),
                "notes": f"absolute coordinates: {report.n_coordinates} q, {report.n_equations} "
                         f"Φ rows of rank {report.rank}"
                         + (f", redundant: {', '.join(report.redundant_labels)}"
                            if report.redundant else "")}

    def method_model_size(self, model: Mechanism, method: str) -> dict:
        """:meth:`model_size`, or the joint-coordinate model's size
        (:func:`~mbh._adapters.inhouse.formulations.joint_coordinates.joint_model_size`) when
        ``method`` runs in joint coordinates (``coords=joint``, or ``auto`` choosing them)."""
        spec, params = self.method_spec(method)
        if self._coordinates(model, spec.name, params)[0] != "joint":
            return self.model_size(model)
        from mbh._adapters.inhouse.bodies.kinematics import common_start

        return joint_model_size(model, common_start(model).q)

    def _mechanism(self, model: Mechanism) -> Mechanism:
        return model

    def _check_params(self, spec: MethodSpec, params: dict) -> None:
        if params.get("loop", LOOPS[0]) not in LOOPS:
            raise ValueError(f"parameter 'loop' of {spec.name!r} must be one of "
                             f"{', '.join(LOOPS)}, got {params['loop']!r}")
        coords = params.get("coords", COORDINATES[0])
        if coords not in COORDINATES:
            raise ValueError(f"parameter 'coords' of {spec.name!r} must be one of "
                             f"{', '.join(COORDINATES)}, got {coords!r}")
        loop = params.get("loop", "python")
        if coords == "joint" and joint_loop(*_split(spec.name), loop) is None:
            raise ValueError(f"parameter 'loop' of {spec.name!r}: coords=joint has no loop={loop}"
                             f" ({joint_loop_unsupported(*_split(spec.name))}); it takes "
                             f"loop={' or loop='.join(JOINT_LOOPS)} where auto is the compiled "
                             "loop where it runs the method, else Python")
        if spec.name == "ida":
            from mbh._adapters.inhouse.formulations.dae import check_ida_params
            check_ida_params(params)

    def bare_loop(self, model: Mechanism, method: str, dt: float, n_steps: int) -> float:
        """The compiled loop alone: ``n_steps`` steps in one call (methods on the compiled path,
        the joint coordinates' one included; the Python path, ``loop=python``, has no loop apart
        from the adapter's)."""
        spec, params = self.method_spec(method)
        loop = params.get("loop", "python")
        joint = self._coordinates(model, spec.name, params)[0] == "joint"
        if loop == "python" or (joint and joint_loop(*_split(spec.name), loop) == "python"):
            raise UnsupportedCase(f"{spec.name} runs on the Python path: no bare loop apart from "
                                  "the adapter's")
        stepper = self._start(model, spec, params, RunGrid(dt, n_steps * dt, np.zeros(1), True))
        began = time.perf_counter()
        stepper._step_to(n_steps * dt)
        return time.perf_counter() - began - stepper.untimed_s

    def _fixed_step(self, spec: MethodSpec, params: dict) -> bool:
        return spec.name != "ida" and not integrator_class(_split(spec.name)[0]).adaptive

    def _start(self, model: Mechanism, spec: MethodSpec, params: dict, grid: RunGrid) -> Stepper:
        if spec.name == "ida":
            return _IdaStepper(model, params, grid)
        integrator, strategy = _split(spec.name)
        coords, note = self._coordinates(model, spec.name, params)
        joint = coords == "joint"
        formulation = (JOINT_FORMULATIONS if joint else FORMULATIONS)[strategy]
        reason = formulation.unsupported_reason(model, integrator_class(integrator))
        if reason:
            raise UnsupportedCase(reason)
        own = {k: v for k, v in params.items() if k in formulation.defaults}
        rest = {k: v for k, v in params.items()
                if k not in formulation.defaults and k not in ("loop", "coords")}
        loop = params.get("loop", "python")
        if joint and joint_loop(integrator, strategy, loop) != "python":
            stepper = JointLoopStepper(model, formulation, integrator, rest, own, grid, loop)
        elif joint:
            stepper = JointStepper(model, formulation, integrator, rest, own, grid)
        elif loop == "python":
            stepper = InhouseStepper(model, formulation, integrator, rest, own, grid)
        else:
            stepper = CompiledStepper(model, formulation, integrator, rest, own, grid, loop)
        if note:
            stepper.notes.insert(0, note)
        return stepper

    @staticmethod
    def _coordinates(model: Mechanism, spec_name: str, params: dict) -> tuple[str, str]:
        """The coordinates a run takes (``coords``; ``auto`` resolved by
        :func:`~mbh._adapters.inhouse.formulations.joint_coordinates.auto_coordinates`) and the
        note saying why, empty when the method named them."""
        coords = params.get("coords", COORDINATES[0])
        if coords != "auto":
            return coords, ""
        loop = params.get("loop", "python")
        return auto_coordinates(model, loop, joint_loop(*_split(spec_name), loop))


class _IdaStepper(Stepper):
    """SUNDIALS IDA on the DAE of motion (:mod:`mbh._adapters.inhouse.formulations.dae`) from the assembled state;
    samples from IDA's interpolant, failures at the last step IDA completed."""

    def __init__(self, mech: Mechanism, params: dict, grid: RunGrid):
        from mbh._adapters.inhouse.bodies.constraints import layout_of
        from mbh._adapters.inhouse.formulations.dae import DaeModel, IdaIntegration
        from mbh._adapters.inhouse.bodies.kinematics import common_start

        super().__init__()
        assembly = common_start(mech)
        self.layout = layout_of(mech)
        model = DaeModel(mech, assembly.q, params["form"])
        self.integration = IdaIntegration(
            model, assembly.q, assembly.v, grid.t_end, rtol=params["rtol"], atol=params["atol"],
            max_steps=params["max_steps"], jacobian=params["jacobian"])

    def _step_to(self, t: float) -> None:
        try:
            self.integration.advance_to(t)
        finally:
            self.steps = self.integration.steps
            self.t_good = self.integration.t

    def _states(self, t: float) -> BodyStates:
        from mbh._adapters.inhouse.bodies.states import body_states

        n = self.integration.model.n
        y = self.integration.state_at(t)
        return body_states(self.layout, y[:n], y[n:2 * n])

    def counters(self) -> dict:
        return {key: value for key, value in self.integration.counters().items()
                if key != "steps" and value is not None}
