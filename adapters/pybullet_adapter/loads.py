"""Loads of a Bullet run, applied before every step (Bullet clears them after each step).

* Loads: gravity; joint actuation on tree joints as a generalised force (``TORQUE_CONTROL``), on cut
  joints as equal and opposite body torques; body forces, body torques and spring-dampers as
  external forces recomputed from the body states before every step.  Bullet clears all of them
  after each step, so they are re-applied every step.
"""

from __future__ import annotations

import functools
from collections.abc import Callable

import numpy as np

from mbh._adapters.pybullet_adapter.build import PybulletModel
from mbh._adapters.pybullet_adapter.quiet import pybullet
from mbh._adapters.pybullet_adapter.state import _link_poses, _Pose, _poses, _read_states
from mbh._harness.model.mechanism import (BodyForce, BodyTorque, JointActuation, Mechanism,
                                          SpringDamper)
from mbh._harness.model.trajectory import BodyStates


def _tree_actuation(model: PybulletModel) -> list[tuple[int, float]]:
    """(link, generalised force) of every actuation on a tree joint."""
    mech = model.mechanism
    by_joint = {tj.joint.name: tj for tj in model.tree_joints}
    actuation = []
    for force in mech.forces:
        if isinstance(force, JointActuation) and force.joint in by_joint:
            tj = by_joint[force.joint]
            link = tj.links[-1] if tj.joint.type == "cylindrical" else tj.links[0]
            actuation.append((link, tj.sign * force.value))
    return actuation


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a × b of two 3-vectors: ``np.cross`` costs ~8 µs a call, this ~2 µs (measured), and the
    loads take several crosses every step."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])


def _body_wrenches(model: PybulletModel, states: BodyStates | dict[int, _Pose]) -> np.ndarray:
    """World force and torque about the centre of mass on each body, shape (n_bodies, 2, 3), from
    the body states or their poses (:func:`~mbh._adapters.pybullet_adapter.state._link_poses`)."""
    mech = model.mechanism
    poses = states if isinstance(states, dict) else _poses(mech, states)
    wrench = np.zeros((len(mech.bodies) + 1, 2, 3))  # last row: ground, discarded
    cut_names = set(model.tree.cut_joints)
    for force in mech.forces:
        if isinstance(force, BodyForce):
            index = mech.body_index(force.body)
            wrench[index, 0] += force.force
            wrench[index, 1] += _cross(poses[index].rotation @ force.point, force.force)
        elif isinstance(force, BodyTorque):
            wrench[mech.body_index(force.body), 1] += force.torque
        elif isinstance(force, SpringDamper):
            _add_spring(mech, force, poses, wrench)
        elif isinstance(force, JointActuation) and force.joint in cut_names:
            joint = mech.joint(force.joint)
            one, two = mech.body_index(joint.body1), mech.body_index(joint.body2)
            torque = force.value * (poses[one].rotation @ joint.axis1)
            wrench[two, 1] += torque
            wrench[one, 1] -= torque
    return wrench[:-1]


def _add_spring(mech: Mechanism, spring: SpringDamper, poses: dict[int, _Pose],
                wrench: np.ndarray) -> None:
    """Add the spring-damper's forces on its two bodies to ``wrench`` (ground row -1)."""
    ends = []
    for name, local in ((spring.body1, spring.point1), (spring.body2, spring.point2)):
        index = mech.body_index(name)
        pose = poses[index]
        arm = pose.rotation @ local
        ends.append((index, arm, pose.position + arm, pose.velocity + _cross(pose.omega, arm)))
    delta = ends[1][2] - ends[0][2]
    length = float(np.linalg.norm(delta))
    direction = delta / length
    rate = float(direction @ (ends[1][3] - ends[0][3]))
    tension = spring.stiffness * (length - spring.free_length) + spring.damping * rate
    for (index, arm, _, _), sign in zip(ends, (1.0, -1.0)):
        force = sign * tension * direction
        wrench[index, 0] += force
        wrench[index, 1] += _cross(arm, force)


def _apply_body_loads(model: PybulletModel, uid: int, client: int) -> None:
    """Apply this step's body wrenches, recomputed from the body states (Bullet clears them
    every step)."""
    poses = _link_poses(model, uid, client)
    if poses is None:
        poses = _poses(model.mechanism, _read_states(model, uid, client))
    for index, (force, torque) in enumerate(_body_wrenches(model, poses)):
        link = model.body_links[index]
        if np.any(force):
            pybullet.applyExternalForce(uid, link, list(force), list(poses[index].position),
                                        pybullet.WORLD_FRAME, physicsClientId=client)
        if np.any(torque):
            pybullet.applyExternalTorque(uid, link, list(torque), pybullet.WORLD_FRAME,
                                         physicsClientId=client)


def _loaded_steps(model: PybulletModel, uid: int, client: int) -> Callable[[int], None]:
    """A function taking ``count`` steps of the world, each after applying its loads: the joint
    torques of tree actuation (``TORQUE_CONTROL``) and, when some load depends on the state, the
    body wrenches.  No checks: this is both the adapter's stepping and its bare loop."""
    loads = [functools.partial(pybullet.setJointMotorControl2, uid, link,
                               pybullet.TORQUE_CONTROL, force=value, physicsClientId=client)
             for link, value in _tree_actuation(model)]
    if _needs_body_loads(model):
        loads.append(functools.partial(_apply_body_loads, model, uid, client))
    step = functools.partial(pybullet.stepSimulation, physicsClientId=client)

    def steps(count: int) -> None:
        for _ in range(count):
            for apply in loads:
                apply()
            step()

    return steps


def _needs_body_loads(model: PybulletModel) -> bool:
    """True when some load must be recomputed from the body states every step."""
    cut_names = set(model.tree.cut_joints)
    return any(isinstance(f, (BodyForce, BodyTorque, SpringDamper))
               or (isinstance(f, JointActuation) and f.joint in cut_names)
               for f in model.mechanism.forces)
