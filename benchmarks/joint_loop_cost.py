"""Cost of a joint-coordinate step (``coords=joint``) on the Python loop and on the compiled loop
(adapters/inhouse/stepping/compiled_joint.py), side by side in one run, with the absolute model
and MuJoCo beside them.

Run:  .venv/bin/python benchmarks/joint_loop_cost.py [scene ...]

For each scene (default: bricard, fourbar, fourbar_spatial, slider_crank, simple_pendulum) at
dt = 1e-2 s (1e-3 s for the four-bars), over the first second, it prints µs per step (the run's
wall time, samples read at every step left out as the harness leaves them out, over its steps;
best of five runs after one that compiles or loads):

* ab5+baumgarte:coords=joint and rk4+baumgarte:coords=joint with ``loop=python``, with the
  compiled loop on the kernel (``loop=compiled``) and with the right-hand side generated for the
  mechanism (``loop=generated``, the default);
* one joint-coordinate right-hand side called from Python (µs per call, best of five rounds of
  2,000), what a step costs at least: ab5 makes one a step, rk4 four;
* the absolute model (``ab5+baumgarte``, its default loop) and MuJoCo ``best``.

Nothing here is asserted.
"""

from __future__ import annotations

import sys
import timeit

import numpy as np

from mbh._adapters import get_adapter
from mbh._adapters.inhouse.bodies.kinematics import common_start
from mbh._adapters.inhouse.formulations.joint_coordinates import JointBaumgarte
from mbh._harness.model import scenario
from mbh._harness.model.timegrid import sample_times

SCENES = ("bricard", "fourbar", "fourbar_spatial", "slider_crank", "simple_pendulum")
STEP = {"fourbar": 1e-3, "fourbar_spatial": 1e-3}
T_END, REPEATS, CALLS = 1.0, 5, 2000
COLUMNS = [("inhouse", "ab5+baumgarte:coords=joint,loop=python", "ab5 py"),
           ("inhouse", "ab5+baumgarte:coords=joint,loop=compiled", "ab5 comp"),
           ("inhouse", "ab5+baumgarte:coords=joint,loop=generated", "ab5 gen"),
           ("inhouse", "rk4+baumgarte:coords=joint,loop=python", "rk4 py"),
           ("inhouse", "rk4+baumgarte:coords=joint,loop=compiled", "rk4 comp"),
           ("inhouse", "rk4+baumgarte:coords=joint,loop=generated", "rk4 gen"),
           ("inhouse", "ab5+baumgarte", "abs ab5"),
           ("mujoco", "best", "mujoco")]


def per_step_us(adapter: str, mech, method: str, dt: float) -> float:
    """Best of :data:`REPEATS` runs' wall time per step, µs (after one untimed run)."""
    engine = get_adapter(adapter)
    model, samples = engine.build(mech), sample_times(dt, T_END)
    best = np.inf
    for _ in range(REPEATS + 1):
        run = engine.simulate(model, method, dt, T_END, samples)
        if run.status != "ok":
            return float("nan")
        best = min(best, run.wall_time_s / run.steps)
    return best * 1e6


def rhs_us(mech) -> float:
    """One joint-coordinate right-hand side called from Python at the start, µs."""
    start = common_start(mech)
    model = JointBaumgarte(mech, start.q, 1e-2)
    theta, rate = model.reduce(start.q, start.v)
    model.acceleration(0.0, theta, rate)
    calls = timeit.repeat(lambda: model.acceleration(0.0, theta, rate), number=CALLS,
                          repeat=REPEATS)
    return min(calls) / CALLS * 1e6


def main(names) -> None:
    print(f"µs per step (best of {REPEATS}), first {T_END:g} s; rhs: one joint right-hand side")
    print(f"{'scene':16s} {'dt':>6s} " + " ".join(f"{label:>9s}" for *_, label in COLUMNS)
          + f" {'rhs':>7s}")
    for name in names:
        mech = scenario.load(name)
        dt = STEP.get(name, 1e-2)
        costs = [per_step_us(adapter, mech, method, dt) for adapter, method, _ in COLUMNS]
        print(f"{name:16s} {dt:6g} " + " ".join(f"{cost:9.2f}" for cost in costs)
              + f" {rhs_us(mech):7.2f}", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:] or SCENES)
