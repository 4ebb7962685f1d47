"""Conservation laws along the engines' runs: energy of conservative mechanisms, momentum of
systems no outside torque or force acts on.

A mechanism without damping and actuation, loaded only by gravity, keeps T + V constant
(Lagrange; the ideal joints' reactions do no work); a rigid body on a ball joint at its centre of
mass, gravity acting there too, keeps its angular momentum about that centre (Euler 1765, the
torque-free body of Euler–Poinsot; Landau & Lifshitz, Mechanics, §37); a system joined to nothing
keeps its linear and angular momentum (Newton's third law for the joint's reactions).  T, V and
the momenta are computed here from the body states and the masses and inertias the engines are
given (:mod:`tests.outside.independent`): A I Aᵀ with A the quaternion's rotation, not the
harness's energy bookkeeping.

The harness lets a mechanism have no joint to ground (``floating_pair``: the in-house
formulation and Exudyn run it); MuJoCo, Pinocchio and PyBullet build trees from ground and
report it unsupported ("the system graph is disconnected"), so the torque-free rotor on its ball
joint checks their angular momentum.

Measured on 2026-11-29 at dt = 1e-3 s (``best``): the largest drift over the run, relative to the
largest kinetic energy of the run (energy) or to the initial momentum's length.  A bound is
:data:`MARGIN` × the measured drift, never below :data:`FLOOR`.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.helpers import bennett_linkage
from tests.outside.independent import (angular_momentum, engine_cases, kinetic_energy,
                                       mass_properties, mechanical_energy, ok_run)
from tests.outside.mechanisms import floating_pair, free_fourbar, torque_free_rotor

#: A bound is this multiple of the measured drift (integration errors: the same on any CPU up
#: to round-off) ...
MARGIN = 3.0
#: ... and never below this relative drift: the in-house, MuJoCo and Pinocchio runs of the rotor
#: and the pair drift by 1e-13 to 2e-12 (round-off over 1000 steps); 50× the largest of these
#: allows another CPU's summation order, while a missing gyroscopic term or a misplaced joint
#: drifts by ≥ 1e-3.
FLOOR = 1e-10
DT = 1e-3
#: Mechanism → (builder, end time in s).
MECHANISMS = {"bennett": (bennett_linkage, 1.0), "fourbar_free": (free_fourbar, 2.0),
              "torque_free_rotor": (torque_free_rotor, 1.0), "floating_pair": (floating_pair, 1.0)}
#: Engines that do not run a mechanism ok, with the status and reason measured.
NOT_OK = {
    "bennett": {
        "exudyn": "failed: engine limit: Exudyn's Newton iteration on redundant equations "
                  "(23 algebraic equations on 21 coordinates: at least 3 redundant …): exudyn "
                  "solver failed: reduction of step size reached minimum step size … "
                  "(overconstrained loop: 3 of the 20 joint equations are redundant)",
        "pybullet": "unsupported: cut joint 'J2' is revolute: a Bullet multibody closes loops "
                    "only with point-to-point constraints"},
    "fourbar_free": {},
    "torque_free_rotor": {},
    "floating_pair": {engine: f"unsupported: {engine} builds its model as a tree of joints from "
                              "the ground: … the system graph is disconnected; no chain of joints "
                              "links 'left', 'right' to ground"
                      for engine in ("mujoco", "pinocchio", "pybullet")},
}
#: Largest |E − E(0)| / max T per mechanism and engine (max T: Bennett 2.0 J, four-bar 8756 J,
#: rotor 2.9 J, pair 9.6 J; the free four-bar's crank swings through 5.2 rad in its 2 s).
ENERGY_MEASURED = {
    "bennett": {"inhouse": 2.3e-13, "mujoco": 1.6e-8, "pinocchio": 1.23e-6},
    "fourbar_free": {"inhouse": 8.8e-9, "mujoco": 5.3e-6, "pinocchio": 8.7e-9, "exudyn": 2.24e-4,
                     "pybullet": 1.85e-3},
    "torque_free_rotor": {"inhouse": 1.2e-13, "mujoco": 1.3e-13, "pinocchio": 1.3e-13,
                          "exudyn": 2.5e-7, "pybullet": 3.4e-3},
    "floating_pair": {"inhouse": 1.4e-13, "exudyn": 2.9e-7},
}
#: Largest |L − L(0)| / |L(0)| (the rotor's about its centre, |L(0)| = 1.67 kg·m²/s; the pair's
#: about the origin, 4.49 kg·m²/s) and, for the pair, |p − p(0)| / |p(0)|.
MOMENTUM_MEASURED = {
    "torque_free_rotor": {"inhouse": 8.4e-13, "mujoco": 1.7e-12, "pinocchio": 1.7e-12,
                          "exudyn": 1.8e-7, "pybullet": 2.2e-3},
    "floating_pair": {"inhouse": (3.5e-13, 1.1e-13), "exudyn": (2.4e-7, 4.4e-15)},
}


def bound(measured: float) -> float:
    """The test's bound on a relative drift measured at ``measured``."""
    return max(MARGIN * measured, FLOOR)


def run(name: str, engine: str):
    """(mechanism, trajectory) of ``engine``'s ok run of mechanism ``name``."""
    build, t_end = MECHANISMS[name]
    mech = build()
    return mech, ok_run(mech, engine, DT, t_end)


def relative_drift(series: np.ndarray, scale: float) -> float:
    """Largest distance of ``series`` (shape (n,) or (n, 3)) from its first value over
    ``scale``."""
    change = series - series[0]
    return float(np.max(np.linalg.norm(change.reshape(len(series), -1), axis=1)) / scale)


@pytest.mark.parametrize("name, engine", [case for name in MECHANISMS
                                          for case in engine_cases(NOT_OK[name], name)])
def test_conservative_mechanism_keeps_its_energy(name, engine):
    """T + V of a mechanism without damping or actuation (module docstring)."""
    mech, trajectory = run(name, engine)
    drift = relative_drift(mechanical_energy(trajectory, mech),
                           kinetic_energy(trajectory, mech).max())
    assert drift <= bound(ENERGY_MEASURED[name][engine]), f"{name}, {engine}: {drift:.3g}"


@pytest.mark.parametrize("engine", engine_cases(NOT_OK["torque_free_rotor"]))
def test_torque_free_rotor_keeps_its_angular_momentum(engine):
    """Euler–Poinsot: the rotor's (A I Aᵀ) ω is constant while ω itself wanders."""
    mech, trajectory = run("torque_free_rotor", engine)
    rotor = mech.body_index("rotor")
    momentum = angular_momentum(trajectory, mech, [rotor])
    assert np.ptp(trajectory.angular_velocity[:, rotor], axis=0).min() > 1.0
    drift = relative_drift(momentum, np.linalg.norm(momentum[0]))
    assert drift <= bound(MOMENTUM_MEASURED["torque_free_rotor"][engine]), f"{drift:.3g}"


@pytest.mark.parametrize("engine", engine_cases(NOT_OK["floating_pair"]))
def test_floating_pair_keeps_its_momenta(engine):
    """A pair joined to nothing: angular momentum about the origin and linear momentum."""
    mech, trajectory = run("floating_pair", engine)
    masses, _ = mass_properties(mech)
    linear = np.einsum("b,tbi->ti", masses, trajectory.velocity)
    angular = angular_momentum(trajectory, mech)
    found = (relative_drift(angular, np.linalg.norm(angular[0])),
             relative_drift(linear, np.linalg.norm(linear[0])))
    allowed = tuple(bound(value) for value in MOMENTUM_MEASURED["floating_pair"][engine])
    assert found[0] <= allowed[0] and found[1] <= allowed[1], f"{found} > {allowed}"
