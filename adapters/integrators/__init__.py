"""The in-house integrator library for q̈ = a(t, q, v) (Rouvinen 2003, ch. 4).

Methods are looked up by their literature name::

    integrator = make_integrator("rk4", problem, t0, q0, v0, dt)
    while integrator.t < t_end and integrator.step() == IntegratorState.RUNNING:
        ...

========================  =====  =========================================================
name                      order  family (module)
========================  =====  =========================================================
euler                     1      explicit one-step, eq. 98 (:mod:`.nystrom`)
symplectic-euler          1      explicit one-step
heun                      2      explicit one-step, eqs. 99–101
rk4                       4      explicit one-step, eqs. 102–106
rkn4                      4      Runge–Kutta–Nyström
rk5                       5      explicit one-step, Dormand–Prince (RK45's formula)
rk8                       8      explicit one-step, Dormand–Prince (DOP853's formula)
ab1 … ab5                 k      Adams–Bashforth, table 2 (:mod:`.multistep`)
am1 … am5                 k      Adams–Moulton of order k, table 3, Newton
abm4                      4      AB4–AM4 predictor–corrector, PECE, fig. 15
bdf1 … bdf4               p      Gear, table 4, Newton with a re-used Jacobian
rk45 dop853 radau bdf     –      adaptive SciPy solvers (:mod:`.scipy_solvers`)
lsoda
========================  =====  =========================================================
"""

from __future__ import annotations

from mbh._adapters.integrators.base import Integrator, SecondOrderProblem, SecondOrderSystem
from mbh._adapters.integrators.multistep import (
    ABM4,
    ADAMS_BASHFORTH_METHODS,
    ADAMS_MOULTON_METHODS,
    GEAR_METHODS,
)
from mbh._adapters.integrators.nystrom import RK4, RK5, RK8, RKN4, Euler, Heun, SymplecticEuler
from mbh._adapters.integrators.scipy_solvers import SCIPY_METHODS
from mbh._harness.common.status import IntegratorState

__all__ = [
    "INTEGRATORS", "Integrator", "IntegratorState", "SecondOrderProblem",
    "SecondOrderSystem", "integrator_class", "integrator_names", "integrator_params",
    "is_adaptive", "make_integrator",
]

#: Every method by its user-facing name.
INTEGRATORS: dict[str, type[Integrator]] = {
    cls.name: cls
    for cls in (Euler, SymplecticEuler, Heun, RK4, RKN4, RK5, RK8, *ADAMS_BASHFORTH_METHODS,
                *ADAMS_MOULTON_METHODS, ABM4, *GEAR_METHODS, *SCIPY_METHODS)
}


def integrator_names() -> list[str]:
    """Names of every method, in the order of the table above."""
    return list(INTEGRATORS)


def integrator_class(name: str) -> type[Integrator]:
    """The class of method ``name``; an unknown name raises a ValueError listing the valid ones."""
    try:
        return INTEGRATORS[name]
    except KeyError:
        raise ValueError(f"unknown integrator {name!r}; valid: "
                         f"{', '.join(INTEGRATORS)}") from None


def integrator_params(name: str) -> dict:
    """Parameters of method ``name`` with their default values."""
    return integrator_class(name).parameter_defaults()


def is_adaptive(name: str) -> bool:
    """True for the adaptive SciPy solvers, False for the fixed-step methods."""
    return integrator_class(name).adaptive


def make_integrator(name, problem, t0, q0, v0, dt, **params) -> Integrator:
    """Construct method ``name`` (see :class:`~.base.Integrator` for the arguments)."""
    return integrator_class(name)(problem, t0, q0, v0, dt, **params)
