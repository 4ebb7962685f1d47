"""A live Bullet world of a :class:`~mbh._adapters.pybullet_adapter.build.PybulletModel`: a fresh DIRECT
client with the method's settings, the multibody, the cut-joint constraints and the faithfulness
switches, at the harness's initial state (:func:`bullet_world`).

Faithfulness switches (each has a test): joint velocity motors off (revolute/prismatic force 0,
spherical motor force 0), linear/angular damping 0, joint damping and friction 0, the 100 rad/s
joint-velocity clamp raised to :data:`_HUGE`, the user-constraint force cap raised to :data:`_HUGE`
after the time step is set, sleeping disabled, no collision shapes (so no contacts), inertia set
explicitly (links without a collision shape otherwise get zero inertia).
"""

from __future__ import annotations

import contextlib
import itertools
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from mbh._adapters.pybullet_adapter.build import PybulletModel, _Link
from mbh._adapters.pybullet_adapter.quiet import _quiet_output, pybullet
from mbh._adapters.pybullet_adapter.state import _quat_xyzw, _reset_state
from mbh._harness.neutral.start import initial_state

#: Stand-in for "no limit" in Bullet settings that take a finite number (N, N·m, rad/s, m/s).
_HUGE = 1e30


def _inertial_frame(model: PybulletModel, link: _Link) -> tuple[list, list]:
    """Inertial frame position and orientation (x, y, z, w) of ``link`` in its link frame."""
    if link.body < 0:
        return [0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]
    body = model.mechanism.bodies[link.body]
    return list(body.position - link.origin), _quat_xyzw(body.rotation @ model.principal[link.body])


def _create_multibody(model: PybulletModel, client: int) -> int:
    """Create the multibody (no collision or visual shapes) and return its unique id."""
    links = model.links
    origins = [np.zeros(3) if link.parent < 0 else links[link.parent].origin for link in links]
    inertial = [_inertial_frame(model, link) for link in links]
    return pybullet.createMultiBody(
        baseMass=0.0, baseCollisionShapeIndex=-1, baseVisualShapeIndex=-1,
        basePosition=[0.0, 0.0, 0.0], baseOrientation=[0.0, 0.0, 0.0, 1.0],
        linkMasses=[0.0 if link.body < 0 else model.mechanism.bodies[link.body].mass
                    for link in links],
        linkCollisionShapeIndices=[-1] * len(links), linkVisualShapeIndices=[-1] * len(links),
        linkPositions=[list(link.origin - o) for link, o in zip(links, origins)],
        linkOrientations=[[0.0, 0.0, 0.0, 1.0]] * len(links),
        linkInertialFramePositions=[pos for pos, _ in inertial],
        linkInertialFrameOrientations=[orn for _, orn in inertial],
        linkParentIndices=[link.parent + 1 for link in links],
        linkJointTypes=[link.joint_type for link in links],
        linkJointAxis=[list(link.axis) for link in links],
        physicsClientId=client,
    )


class LinkOrderError(RuntimeError):
    """Bullet's link indices are not the model's link indices (the model would read wrong links)."""


def _check_link_order(model: PybulletModel, uid: int, client: int) -> None:
    """Read every link's name back from Bullet and require link ``i`` to be created link ``i``.

    ``createMultiBody`` names the link created at position ``k`` (0-based) ``link{k + 1}`` and
    re-sorts links depth-first; :func:`~mbh._adapters.pybullet_adapter.build.build_model` creates them
    in that order, so the read-back names must run ``link1, link2, …``.

    Raises
    ------
    LinkOrderError
        Naming the first Bullet link that holds a different created link.
    """
    count = pybullet.getNumJoints(uid, physicsClientId=client)
    names = [pybullet.getJointInfo(uid, index, physicsClientId=client)[12].decode()
             for index in range(count)]
    expected = [f"link{index + 1}" for index in range(len(model.links))]
    wrong = [(index, name, want) for index, (name, want)
             in enumerate(itertools.zip_longest(names, expected)) if name != want]
    if wrong:
        index, name, want = wrong[0]
        raise LinkOrderError(f"Bullet link {index} is {name!r}, expected {want!r}: Bullet "
                             "re-sorted the links, so states would be written to and read from "
                             "the wrong bodies")


def _make_faithful(model: PybulletModel, uid: int, client: int) -> None:
    """Switch off everything Bullet adds to the mechanism (see the module docstring)."""
    for index, link in enumerate(model.links):
        moments = [0.0] * 3 if link.body < 0 else list(model.moments[link.body])
        # Its own call: combined with linearDamping, angularDamping, maxJointVelocity or
        # activationState, changeDynamics silently leaves the inertia at zero.
        pybullet.changeDynamics(uid, index, localInertiaDiagonal=moments, physicsClientId=client)
        pybullet.changeDynamics(uid, index, linearDamping=0.0,
                                angularDamping=0.0, jointDamping=0.0, maxJointVelocity=_HUGE,
                                activationState=pybullet.ACTIVATION_STATE_DISABLE_SLEEPING,
                                physicsClientId=client)
        if link.joint_type == pybullet.JOINT_SPHERICAL:
            pybullet.setJointMotorControlMultiDof(uid, index, pybullet.POSITION_CONTROL,
                                                  targetPosition=[0.0, 0.0, 0.0, 1.0],
                                                  positionGain=0.0, velocityGain=0.0,
                                                  force=[0.0, 0.0, 0.0], physicsClientId=client)
        else:
            pybullet.setJointMotorControl2(uid, index, pybullet.VELOCITY_CONTROL, force=0.0,
                                           physicsClientId=client)
    pybullet.changeDynamics(uid, -1, linearDamping=0.0, angularDamping=0.0,
                            activationState=pybullet.ACTIVATION_STATE_DISABLE_SLEEPING,
                            physicsClientId=client)


def pivot(model: PybulletModel, body: int, local: np.ndarray) -> list[float]:
    """A body-frame point in the centre-of-mass (principal) frame Bullet's pivots use."""
    return list(local) if body < 0 else list(model.principal[body].T @ local)


def _add_cut_constraints(model: PybulletModel, uid: int, client: int) -> list[int]:
    """Create the point-to-point constraints with no force cap; returns their ids.

    Call after the time step is set: ``maxForce`` is stored as an impulse cap (force × step).
    """
    ids = []
    for cut in model.cuts:
        link1 = -1 if cut.body1 < 0 else model.body_links[cut.body1]
        link2 = -1 if cut.body2 < 0 else model.body_links[cut.body2]
        cid = pybullet.createConstraint(
            uid, link1, uid, link2, pybullet.JOINT_POINT2POINT, [0.0, 0.0, 0.0],
            pivot(model, cut.body1, cut.joint.point1), pivot(model, cut.body2, cut.joint.point2),
            physicsClientId=client)
        pybullet.changeConstraint(cid, maxForce=_HUGE, physicsClientId=client)
        ids.append(cid)
    return ids


def _set_parameters(params: dict, dt: float, gravity: np.ndarray, client: int) -> None:
    """Time step, gravity and every solver setting of the method."""
    pybullet.setGravity(*map(float, gravity), physicsClientId=client)
    settings = dict(params)
    settings["useSplitImpulse"] = int(settings["useSplitImpulse"])
    with _quiet_output():  # the MLCP solvers announce themselves on stdout
        pybullet.setPhysicsEngineParameter(fixedTimeStep=dt, physicsClientId=client, **settings)


@contextlib.contextmanager
def _client() -> Iterator[int]:
    """A fresh DIRECT physics client, disconnected on exit."""
    with _quiet_output():
        client = pybullet.connect(pybullet.DIRECT)
    try:
        yield client
    finally:
        pybullet.disconnect(physicsClientId=client)


@dataclass(frozen=True)
class BulletWorld:
    """A live Bullet world of a model: physics client, multibody id and cut-constraint ids."""

    client: int
    body: int
    constraints: tuple[int, ...]


@contextlib.contextmanager
def bullet_world(model: PybulletModel, params: dict | None, dt: float) -> Iterator[BulletWorld]:
    """Build ``model`` in a fresh DIRECT client, faithful and at the harness's initial state.

    Parameters
    ----------
    model : PybulletModel
    params : dict or None
        Resolved method parameters; None leaves every solver setting at PyBullet's own value
        (only the time step and gravity are set).
    dt : float
        Time step, s.
    """
    with _client() as client:
        if params is None:
            pybullet.setGravity(*map(float, model.mechanism.gravity), physicsClientId=client)
            pybullet.setTimeStep(dt, physicsClientId=client)
        else:
            _set_parameters(params, dt, model.mechanism.gravity, client)
        uid = _create_multibody(model, client)
        _check_link_order(model, uid, client)
        _make_faithful(model, uid, client)
        constraints = _add_cut_constraints(model, uid, client)
        _reset_state(model, uid, initial_state(model.mechanism), client)
        yield BulletWorld(client, uid, tuple(constraints))
