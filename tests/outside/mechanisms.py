"""Mechanisms of the outside tests that tests/helpers.py does not draw: the seed four-bar left to
gravity, a torque-free rotor and a pair of bodies with no joint to ground.  Each is conservative:
no damping, no actuation, and gravity (a potential) or none."""

from __future__ import annotations

import tomllib

import mbh
from mbh._harness.model.scenario import scenario_path


def free_fourbar(rate: float = -2.0):
    """Rouvinen's four-bar (``scenarios/fourbar.toml``, planar) without its driving torque:
    gravity alone, the crank started at ``rate`` (rad/s), for 2 s."""
    document = tomllib.loads(scenario_path("fourbar").read_text(encoding="utf-8"))
    del document["forces"]
    document.update(tags=[], duration=2.0,
                    notes="The seed four-bar without its torque: conservative.")
    document["initial"]["rate"] = rate
    return mbh.MechanismBuilder("fourbar_free", **document).build()


def torque_free_rotor():
    """A rotor on a spherical joint at its centre of mass: Euler–Poinsot's torque-free rigid body
    (Euler 1765; Landau & Lifshitz, Mechanics, §37).  Its principal moments 0.3, 0.5, 0.7 kg·m²
    are tilted (313 Euler angles 20°, 30°, 40°); it starts at ω = (3, 1, 2) rad/s, set by the
    velocities of two of its points.  The ball joint sits on a cradle turning at 1 rad/s about z
    (the driver a scene needs; the ball passes it no torque), centre on the axis.  Gravity acts
    at the joint, so it exerts no torque either: the rotor's angular momentum about its centre
    and its kinetic energy stay constant."""
    return (mbh.MechanismBuilder("torque_free_rotor", kind="spatial", duration=1.0,
                                 gravity=[0.0, 0.0, -9.81])
            .body("cradle", mass=0.5, inertia=[0.01, 0.01, 0.01], position=[0.0, 0.0, 0.0])
            .body("rotor", mass=2.0, inertia=[0.3, 0.5, 0.7], position=[0.0, 0.0, 0.0],
                  euler313_deg=[20.0, 30.0, 40.0])
            .joint("spin", "revolute", body1="ground", body2="cradle", location=[0.0, 0.0, 0.0],
                   axis=[0.0, 0.0, 1.0])
            .joint("ball", "spherical", body1="cradle", body2="rotor", location=[0.0, 0.0, 0.0])
            # v = ω × p: at (1, 0, 0) (vy, vz) = (ωz, −ωy), at (0, 1, 0) vz = ωx.
            .initial(driver="spin", value=0.0, rate=1.0, velocities=[
                {"body": "rotor", "location": [1.0, 0.0, 0.0], "velocity": [0.0, 2.0, -1.0],
                 "components": ["y", "z"]},
                {"body": "rotor", "location": [0.0, 1.0, 0.0], "velocity": [0.0, 0.0, 3.0],
                 "components": ["z"]}])
            .output("spin_angle", "joint_angle", joint="spin").build())


def floating_pair():
    """Two bodies hinged together and joined to nothing else, without gravity: a free system
    whose linear and angular momentum and energy stay constant.  The hinge is tilted, the
    inertias unequal; the start is set in full: the hinge's rate and the velocities of three
    points of the first body (its centre's, then two more giving its angular velocity)."""
    return (mbh.MechanismBuilder("floating_pair", kind="spatial", duration=1.0,
                                 gravity=[0.0, 0.0, 0.0])
            .body("left", mass=1.0, inertia=[0.1, 0.2, 0.25], position=[-0.5, 0.0, 0.0])
            .body("right", mass=2.0, inertia=[0.3, 0.15, 0.4], position=[0.6, 0.1, 0.0],
                  euler313_deg=[10.0, 50.0, -30.0])
            .joint("hinge", "revolute", body1="left", body2="right", location=[0.0, 0.0, 0.0],
                   axis=[0.0, 0.6, 0.8])
            .initial(driver="hinge", value=0.0, rate=2.0, velocities=[
                {"body": "left", "location": [-0.5, 0.0, 0.0], "velocity": [0.1, 0.2, 0.3]},
                {"body": "left", "location": [-1.5, 0.0, 0.0], "velocity": [0.0, -1.3, -0.3],
                 "components": ["y", "z"]},
                {"body": "left", "location": [-0.5, 1.0, 0.0], "velocity": [0.0, 0.0, 0.7],
                 "components": ["z"]}])
            .output("hinge_angle", "joint_angle", joint="hinge").build())
