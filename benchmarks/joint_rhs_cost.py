"""Cost of one joint-coordinate right-hand side (``coords=joint``): the Python tree pass and numpy
assembly it had against the compiled call it has, side by side in one run.

Run:  .venv/bin/python benchmarks/joint_rhs_cost.py [scene ...]

For each scene (default: the shipped scenes the joint coordinates run) it prints, in µs per
call at the common start (best of five rounds of 2,000 calls, from Python as the stepper calls
it): the Python version (the tree pass of ``tests/adapters/inhouse/python_tree_pass.py``, the
absolute kernels called from Python, BᵀMB etc. in numpy, the compiled range-space solve), its
tree pass alone, the compiled right-hand side (``JointNone.acceleration``: one call of
:func:`~mbh._adapters.inhouse.formulations.joint_rhs.acceleration_kernel`), the absolute
formulation's Python-called right-hand side for scale, the ratio before / after, the largest
difference of θ̈ relative to max |θ̈|, and the cost of one ``direct`` projection of (θ, θ̇) as it is
now (compiled pass, Newton and the truncated solve called from Python).  Nothing here is
asserted.
"""

from __future__ import annotations

import sys
import timeit
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from mbh._adapters.inhouse.bodies.kinematics import common_start  # noqa: E402
from mbh._adapters.inhouse.formulations.dynamics import (ACCELERATION_CUT,  # noqa: E402
                                                         range_space_acceleration)
from mbh._adapters.inhouse.formulations.joint_coordinates import (JointDirect,  # noqa: E402
                                                                  JointNone)
from mbh._adapters.inhouse.formulations.stabilisation import NoStabilisation  # noqa: E402
from mbh._harness.model import scenario  # noqa: E402
from tests.adapters.inhouse.python_tree_pass import python_tree_pass  # noqa: E402

SCENES = ("simple_pendulum", "fourbar", "slider_crank_planar", "double_fourbar", "andrews",
          "fourbar_spatial", "slider_crank", "bricard")
CALLS, ROUNDS = 2000, 5


def python_acceleration(model: JointNone, theta, rate):
    """θ̈ as the Python right-hand side made it (before the compiled one)."""
    q, b, bias = python_tree_pass(model.kinematics, theta, rate)
    v = b @ rate
    mass, force = model.dynamics.mass_and_forces(0.0, q, v)
    mass_theta = np.ascontiguousarray(b.T @ mass @ b)
    force_theta = b.T @ (force - mass @ bias)
    if not model.closure.m:
        c, gamma = np.zeros((0, model.n)), np.zeros(0)
    else:
        jac = model.closure.jacobian(q, 0.0)
        c = np.ascontiguousarray(jac @ b)
        gamma = np.ascontiguousarray(model.closure.gamma(q, v, 0.0) - jac @ bias)
    return range_space_acceleration(mass_theta, c, force_theta, gamma, ACCELERATION_CUT)


def best_us(call) -> float:
    return min(timeit.repeat(call, number=CALLS, repeat=ROUNDS)) / CALLS * 1e6


def row(name: str) -> str:
    """One scene's line of the table (:func:`main`)."""
    mech = scenario.load(name)
    start = common_start(mech)
    model = JointNone(mech, start.q, 1e-3)
    direct = JointDirect(mech, start.q, 1e-3)
    absolute = NoStabilisation(mech, start.q, 1e-3)
    theta, rate = model.reduce(start.q, start.v)
    before = python_acceleration(model, theta, rate)
    after = model.acceleration(0.0, theta, rate)
    absolute.acceleration(0.0, start.q, start.v)
    gap = float(np.abs(after - before).max() / max(np.abs(before).max(), 1e-300))
    old = best_us(lambda: python_acceleration(model, theta, rate))
    tree = best_us(lambda: python_tree_pass(model.kinematics, theta, rate))
    new = best_us(lambda: model.acceleration(0.0, theta, rate))
    scale = best_us(lambda: absolute.acceleration(0.0, start.q, start.v))
    project = best_us(lambda: direct.project(0.0, theta, rate))
    return (f"{name:20s} {old:8.1f} {tree:8.1f} {new:9.1f} {scale:9.1f} {old / new:6.1f} "
            f"{gap:10.1e} {project:9.1f}")


def main(names) -> None:
    print(f"{'scene':20s} {'python':>8s} {'(pass)':>8s} {'compiled':>9s} {'absolute':>9s} "
          f"{'ratio':>6s} {'rel. diff':>10s} {'project':>9s}   (µs per call)")
    for name in names:
        print(row(name), flush=True)


if __name__ == "__main__":
    main(sys.argv[1:] or SCENES)
