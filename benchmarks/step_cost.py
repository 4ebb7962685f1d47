"""Per-step cost of the in-house formulation and where the time goes.

Run:  .venv/bin/python benchmarks/step_cost.py

For rk4+baumgarte and rk4+direct on fourbar and slider_crank it prints the wall time per step of
the compiled loop alone (``Adapter.bare_loop``, best of five 1 s runs at dt = 1e-3), with the
generated functions (``loop=generated``, :mod:`mbh._adapters.inhouse.codegen.generated`) and with the generic
kernels (``loop=compiled``), then the cost of one call of each piece of a right-hand side at the
assembled state, each timed inside a compiled loop (so without Python's call overhead): Φ_q, γ,
the forces Q_e + Q_v, the projection of ``direct`` (Rouvinen 2003, eq. 127 and 137) and the whole fused
acceleration (:func:`~mbh._adapters.inhouse.formulations.dynamics.index1_acceleration`: the pieces plus the mass
matrix solve), the last two by the kernels and by the generated functions.  RK4 makes four
right-hand sides and one projection per step.  Numbers are measured on the machine that runs the
script; nothing here is asserted.
"""

from __future__ import annotations

import time

import numpy as np
from numba import njit

from mbh._adapters import get_adapter
from mbh._adapters.base import RunGrid
from mbh._adapters.inhouse.bodies import kernels
from mbh._adapters.inhouse.stepping.kernel_step import project_state
from mbh._adapters.inhouse.stepping.loop_codes import COUNTERS
from mbh._adapters.inhouse.formulations.dynamics import index1_acceleration
from mbh._adapters.inhouse.formulations.mass_and_forces import forces_kernel
from mbh._adapters.inhouse.codegen.generated import ACCELERATION, NOTHING
from mbh._harness.model import scenario

CASES = [("fourbar", "rk4+baumgarte"), ("fourbar", "rk4+direct"),
         ("slider_crank", "rk4+baumgarte"), ("slider_crank", "rk4+direct")]
DT, STEPS, CALLS = 1e-3, 1000, 20000


def per_step_us(name: str, method: str) -> float:
    """Best of five bare compiled loops of ``STEPS`` steps, µs per step."""
    adapter, mech = get_adapter("inhouse"), scenario.load(name)
    return 1e6 * min(adapter.bare_loop(mech, method, DT, STEPS) for _ in range(5)) / STEPS


#: The pieces timed by :func:`_calls`, in its ``piece`` codes' order.
PIECES = ("jacobian", "gamma", "forces", "projection (kernels)", "projection (generated)",
          "acceleration (kernel)", "acceleration (generated)")


@njit
def _calls(piece, q, v, rows, constraint_args, dynamics_args, sparsity_arrays, functions, n):
    """``n`` calls of one piece (index into :data:`PIECES`); a sum so none is optimised away."""
    total = 0.0
    counters = np.zeros(COUNTERS, dtype=np.int64)
    out = np.empty(q.shape[0])
    for _ in range(n):
        if piece == 0:
            total += kernels.jacobian(q, 0.0, constraint_args)[0, 0]
        elif piece == 1:
            total += kernels.gamma(q, v, 0.0, constraint_args)[0]
        elif piece == 2:
            total += forces_kernel(q, v, *dynamics_args)[0]
        elif piece == 3:
            total += project_state(q, v, 0.0, rows, 1e-12, 10, 1e-10, constraint_args,
                              sparsity_arrays, NOTHING, counters)[0][0]
        elif piece == 4:
            total += project_state(q, v, 0.0, rows, 1e-12, 10, 1e-10, constraint_args,
                              sparsity_arrays, functions, counters)[0][0]
        elif piece == 5:
            total += index1_acceleration(q, v, 0.0, 0.0, 0.0, rows, constraint_args,
                                         dynamics_args, sparsity_arrays)[0]
        else:
            total += functions[ACCELERATION](q, v, 0.0, out) + out[0]
    return total


def kernel_us(name: str) -> dict:
    """Microseconds per call of each piece (best of five loops of ``CALLS`` calls)."""
    adapter, mech = get_adapter("inhouse"), scenario.load(name)
    spec, params = adapter.method_spec("rk4+direct:loop=generated")
    stepper = adapter._start(mech, spec, params, RunGrid(DT, DT, np.zeros(1), True))
    _, rows, constraint_args, dynamics_args, sparsity_arrays, functions = stepper._model[:6]
    arguments = (stepper.q, stepper.v + 0.1, rows, constraint_args, dynamics_args,
                 sparsity_arrays, functions)
    costs = {}
    for piece, key in enumerate(PIECES):
        _calls(piece, *arguments, 1)  # compile
        best = np.inf
        for _ in range(5):
            began = time.perf_counter()
            _calls(piece, *arguments, CALLS)
            best = min(best, time.perf_counter() - began)
        costs[key] = 1e6 * best / CALLS
    return costs


def main() -> None:
    print(f"compiled loop, µs per step, dt = {DT:g} s ({STEPS} steps, best of 5)")
    for name, method in CASES:
        for loop in ("generated", "compiled"):
            print(f"  {name:14s} {method:15s} {loop:10s} "
                  f"{per_step_us(name, f'{method}:loop={loop}'):8.1f} µs/step")
    for name in ("fourbar", "slider_crank"):
        costs = kernel_us(name)
        print(f"one call on {name}, µs (inside a compiled loop): "
              + ", ".join(f"{k} {v:.2f}" for k, v in costs.items()))


if __name__ == "__main__":
    main()
