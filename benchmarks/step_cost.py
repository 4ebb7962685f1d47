"""Per-step cost of the in-house formulation and where the time goes.

Run:  .venv/bin/python benchmarks/step_cost.py

For rk4+baumgarte and rk4+direct on fourbar and slider_crank it prints the wall time per step
(median of three 1 s runs at dt = 1e-3, after a warm-up that compiles the kernels) and the cost of
one call of each compiled kernel at the assembled state, so the share of the step spent in compiled
arithmetic versus Python glue can be read off side by side.  Numbers are measured on the machine
that runs the script; nothing here is asserted.
"""

from __future__ import annotations

import statistics
import timeit

from adapters import get_adapter
from adapters.inhouse.dynamics import solve_augmented
from adapters.inhouse.kinematics import assemble
from adapters.inhouse.stabilisation import NoStabilisation
from harness import scenario
from harness.sampling import sample_times

CASES = [("fourbar", "rk4+baumgarte"), ("fourbar", "rk4+direct"),
         ("slider_crank", "rk4+baumgarte"), ("slider_crank", "rk4+direct")]
DT, T_END = 1e-3, 1.0


def per_step_us(name: str, method: str) -> float:
    adapter = get_adapter("inhouse")
    mech = scenario.load(name)
    times = sample_times(DT, T_END)
    adapter.simulate(mech, method, DT, 0.01, times[:2])  # compile and warm caches
    runs = [adapter.simulate(mech, method, DT, T_END, times) for _ in range(3)]
    return statistics.median(1e6 * r.wall_time_s / r.steps for r in runs)


def kernel_us(name: str) -> dict:
    """Microseconds per call of each piece of one right-hand-side evaluation."""
    mech = scenario.load(name)
    assembly = assemble(mech)
    formulation = NoStabilisation(mech, assembly.q, DT)
    q, v = assembly.q, assembly.v + 0.1
    mass, force = formulation.dynamics.mass_and_forces(0.0, q, v)
    jac = formulation.jacobian(0.0, q)
    gamma = formulation.gamma(0.0, q, v)
    pieces = {
        "jacobian": lambda: formulation.constraints.jacobian(q),
        "gamma": lambda: formulation.constraints.gamma(q, v),
        "mass+forces": lambda: formulation.dynamics.mass_and_forces(0.0, q, v),
        "augmented solve": lambda: solve_augmented(mass, jac, force, gamma),
        "whole acceleration()": lambda: formulation.acceleration(0.0, q, v),
    }
    return {key: 1e6 * min(timeit.repeat(f, number=200, repeat=5)) / 200 for key, f in pieces.items()}


def main() -> None:
    print(f"per-step wall time, dt = {DT:g} s over {T_END:g} s (median of 3)")
    for name, method in CASES:
        print(f"  {name:14s} {method:15s} {per_step_us(name, method):8.1f} µs/step")
    for name in ("fourbar", "slider_crank"):
        costs = kernel_us(name)
        compiled = sum(v for k, v in costs.items() if k != "whole acceleration()")
        whole = costs["whole acceleration()"]
        print(f"one right-hand side on {name}: " + ", ".join(f"{k} {v:.1f} µs" for k, v in costs.items()))
        print(f"  compiled kernels {compiled:.1f} µs of {whole:.1f} µs "
              f"({100 * compiled / whole:.0f} %); RK4 makes 4 per step")


if __name__ == "__main__":
    main()
