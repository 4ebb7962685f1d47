"""Applied loads of a MuJoCo model: the mechanism's forces sorted into constant generalized and
body loads (``qfrc_applied``, ``xfrc_applied``) and pose-dependent ones recomputed every step.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from mbh._harness.model.mechanism import (GROUND, BodyForce, BodyTorque, Joint, JointActuation,
                                          Mechanism)
from mbh._harness.model.topology import SpanningTree


@dataclass(frozen=True)
class _Loads:
    """Applied loads, split into constant ones and pose-dependent ones.

    Attributes
    ----------
    qfrc : ndarray, shape (nv,)
        Generalized forces on tree-joint dofs (N·m or N).
    xfrc : ndarray, shape (nbody, 6)
        Constant world force and torque on bodies at their centres of mass.
    point_forces : tuple of (int, ndarray (3,), ndarray (3,))
        MuJoCo body id, world force (N), application point in the body frame (m).
    cut_torques : tuple of (int, int, ndarray (3,), float)
        Body ids of ``body1`` (0 = world) and ``body2``, joint axis in ``body1``'s frame, torque
        about it on ``body2`` (N·m; the reaction acts on ``body1``).
    """

    qfrc: np.ndarray
    xfrc: np.ndarray
    point_forces: tuple
    cut_torques: tuple

    @property
    def moving(self) -> bool:
        """True when some load depends on the pose and must be recomputed every step."""
        return bool(self.point_forces or self.cut_torques)


def _body_id(model: mujoco.MjModel, name: str) -> int:
    """MuJoCo body id of ``name`` (0 for ground, the world body)."""
    return 0 if name == GROUND else model.body(name).id


def _joint_dof(model: mujoco.MjModel, joint: Joint) -> int:
    """Dof address of the coordinate that ``JointActuation`` drives on tree joint ``joint``."""
    suffix = "_hinge" if joint.type == "cylindrical" else ""
    return model.jnt_dofadr[model.joint(joint.name + suffix).id]


def _loads(mech: Mechanism, tree: SpanningTree, model: mujoco.MjModel) -> _Loads:
    """Sort the mechanism's forces into constant generalized / body loads and moving ones."""
    qfrc, xfrc = np.zeros(model.nv), np.zeros((model.nbody, 6))
    point_forces, cut_torques = [], []
    for force in mech.forces:
        if isinstance(force, JointActuation):
            joint = mech.joint(force.joint)
            if joint.name in tree.cut_joints:
                cut_torques.append((_body_id(model, joint.body1), _body_id(model, joint.body2),
                                    joint.axis1, force.value))
            else:
                sign = -1.0 if tree.flipped[joint.name] else 1.0
                qfrc[_joint_dof(model, joint)] += sign * force.value
        elif isinstance(force, BodyTorque):
            xfrc[_body_id(model, force.body), 3:] += force.torque
        elif isinstance(force, BodyForce):
            xfrc[_body_id(model, force.body), :3] += force.force
            if np.any(force.point != 0.0):
                point_forces.append((_body_id(model, force.body), force.force, force.point))
    return _Loads(qfrc, xfrc, tuple(point_forces), tuple(cut_torques))


def _moving_wrenches(loads: _Loads, data: mujoco.MjData) -> np.ndarray:
    """``xfrc_applied`` (nbody, 6) at the current pose (``data.xmat`` must be current)."""
    xfrc = loads.xfrc.copy()
    for body, force, point in loads.point_forces:
        xfrc[body, 3:] += np.cross(data.xmat[body].reshape(3, 3) @ point, force)
    for body1, body2, axis, value in loads.cut_torques:
        torque = value * (data.xmat[body1].reshape(3, 3) @ axis)
        xfrc[body2, 3:] += torque
        xfrc[body1, 3:] -= torque
    xfrc[0] = 0.0
    return xfrc
