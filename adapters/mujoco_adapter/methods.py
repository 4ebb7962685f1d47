"""Methods of the MuJoCo adapter: the method specs, validation of their parameters, and the copy of
the compiled model configured with a method's options at a step size.

Methods
-------
Every method takes the parameters ``integrator`` (Euler, RK4, implicit, implicitfast, discrete),
``solref_timeconst`` (s; 0 = 2·dt, the smallest value MuJoCo's ``refsafe`` clamp lets through),
``solref_dampratio``, ``solimp0``, ``solimp1``, ``solimp_width`` (the equality constraints'
softness), ``iterations``, ``tolerance`` and ``solver`` (Newton, CG, PGS).  ``default`` is
MuJoCo's own defaults; ``best`` is RK4 with tight constraints; ``<integrator>`` and
``<integrator>-tight`` cover the product of integrators and the two softness presets.
"""

from __future__ import annotations

import copy

import mujoco

from mbh._adapters.base import MethodSpec

#: Integrator names accepted by the ``integrator`` parameter.
INTEGRATORS = {
    "Euler": mujoco.mjtIntegrator.mjINT_EULER,
    "RK4": mujoco.mjtIntegrator.mjINT_RK4,
    "implicit": mujoco.mjtIntegrator.mjINT_IMPLICIT,
    "implicitfast": mujoco.mjtIntegrator.mjINT_IMPLICITFAST,
    "discrete": mujoco.mjtIntegrator.mjINT_DISCRETE,
}
#: Right-hand-side (mj_forward) evaluations per step.
STAGES = {"Euler": 1, "RK4": 4, "implicit": 1, "implicitfast": 1, "discrete": 1}
SOLVERS = {
    "Newton": mujoco.mjtSolver.mjSOL_NEWTON,
    "CG": mujoco.mjtSolver.mjSOL_CG,
    "PGS": mujoco.mjtSolver.mjSOL_PGS,
}
#: Equality-constraint softness presets: MuJoCo's defaults and near-rigid constraints.
SOFTNESS = {
    "default": {"solref_timeconst": 0.02, "solref_dampratio": 1.0, "solimp0": 0.9,
                "solimp1": 0.95, "solimp_width": 0.001},
    "tight": {"solref_timeconst": 0.0, "solref_dampratio": 1.0, "solimp0": 0.9999,
              "solimp1": 0.9999, "solimp_width": 0.001},
}
#: solimp midpoint and power, MuJoCo's defaults (they only shape the width transition).
SOLIMP_SHAPE = (0.5, 2.0)
SOLVER_DEFAULTS = {"iterations": 100, "tolerance": 1e-8, "solver": "Newton"}


def _check_choice(name: str, value: str, choices: dict) -> None:
    """ValueError naming parameter ``name`` unless ``value`` is one of ``choices``."""
    if value not in choices:
        raise ValueError(f"parameter {name!r} must be one of {', '.join(choices)}, got {value!r}")


def _check_params(params: dict) -> None:
    """Validate resolved method parameters, naming the bad one."""
    _check_choice("integrator", params["integrator"], INTEGRATORS)
    _check_choice("solver", params["solver"], SOLVERS)
    for key in ("solimp0", "solimp1"):
        if not 0.0 < params[key] < 1.0:
            raise ValueError(f"parameter {key!r} must lie in (0, 1), got {params[key]!r}")
    for key in ("solref_timeconst", "solimp_width", "tolerance"):
        if params[key] < 0.0:
            raise ValueError(f"parameter {key!r} must be >= 0, got {params[key]!r}")
    for key in ("solref_dampratio", "iterations"):
        if params[key] <= 0:
            raise ValueError(f"parameter {key!r} must be > 0, got {params[key]!r}")


def _configured(model: mujoco.MjModel, params: dict, dt: float) -> mujoco.MjModel:
    """A copy of ``model`` with the method's options and equality softness at step ``dt``."""
    configured = copy.copy(model)
    configured.opt.timestep = dt
    configured.opt.integrator = INTEGRATORS[params["integrator"]]
    configured.opt.solver = SOLVERS[params["solver"]]
    configured.opt.iterations = params["iterations"]
    configured.opt.tolerance = params["tolerance"]
    configured.eq_solref[:] = (params["solref_timeconst"] or 2.0 * dt, params["solref_dampratio"])
    configured.eq_solimp[:] = (params["solimp0"], params["solimp1"], params["solimp_width"],
                               *SOLIMP_SHAPE)
    return configured


def _method_specs() -> list[MethodSpec]:
    """``default``, ``best`` and every integrator with each softness preset."""
    def spec(name, description, integrator, softness):
        params = {"integrator": integrator, **SOFTNESS[softness], **SOLVER_DEFAULTS}
        return MethodSpec(name, description, params)

    specs = [spec("default", "MuJoCo's defaults: Euler, default equality softness "
                  "(solref 0.02 s / 1, solimp 0.9 / 0.95 / 0.001)", "Euler", "default"),
             spec("best", "RK4 with near-rigid equalities (solref time constant 2·dt, solimp "
                  "0.9999 / 0.9999 / 0.001)", "RK4", "tight")]
    for integrator in INTEGRATORS:
        specs.append(spec(integrator.lower(), f"{integrator} with MuJoCo's default equality "
                          f"softness", integrator, "default"))
        specs.append(spec(f"{integrator.lower()}-tight", f"{integrator} with near-rigid "
                          f"equalities (solref 2·dt, solimp 0.9999)", integrator, "tight"))
    return specs
