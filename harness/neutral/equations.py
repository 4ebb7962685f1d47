"""The neutral model's own joint equations, evaluated on world body states (docs/design.md, rule 2).

Written from the joint definitions of :class:`mbh._harness.model.mechanism.Joint` alone (points, axes and normals
in body frames); the in-house kernels are an independent second implementation, and the two are
tested against each other.  Everything here is numpy, vectorised over any leading sample axes.

Rows and their units
--------------------
With P₁ = r₁ + A₁ ū₁, P₂ = r₂ + A₂ ū₂ the joint points in the world, d = P₂ − P₁, and on body 1 the
world axis a₁ = A₁ axis1, normal h₁ = A₁ normal1 and binormal f₁ = a₁ × h₁ (a₂, h₂ likewise on
body 2):

=====================  ====================================================  ======  =============
row group              residual                                              unit    joint types
=====================  ====================================================  ======  =============
gap x, y(, z)          components of d (world)                               m       revolute,
                                                                                     spherical,
                                                                                     universal
off axis               h₁·d, f₁·d: distance of P₂ from body 1's slide line   m       cylindrical,
                       (planar prismatic: (ẑ × a₁)·d)                                translational,
                                                                                     prismatic
tilt about normal /    atan2(−f₁·a₂, a₁·a₂), atan2(h₁·a₂, a₁·a₂): the angle   rad     revolute,
tilt about binormal    a₂ leans out of a₁ seen along h₁ and along f₁                 cylindrical,
                                                                                     translational,
                                                                                     prismatic
twist about axis       atan2(f₁·h₂, h₁·h₂): rotation of body 2 about the     rad     translational,
                       axis (the joint angle, zero in the reference                  prismatic
                       configuration where the normals coincide)
cross axes             atan2(a₁·a₂, |a₁ × a₂|) = asin(a₁·a₂)                  rad     universal
relative angle         φ₂ − φ₁ − (φ₂ − φ₁)_ref wrapped to (−π, π]; φ the       rad     planar
                       angle of a body's x axis about z                              prismatic
=====================  ====================================================  ======  =============

The optional driver row is the driver joint's coordinate minus value + rate·t: the twist angle
(spatial revolute, cylindrical), the relative angle (planar revolute), or the slide a₁·d measured
from the reference configuration (prismatic, translational); angles wrapped to (−π, π], so a joint
that has turned by 2π shows no false violation.

Derivatives are taken with respect to body twists: the centre-of-mass velocity v and the angular
velocity ω in world axes (spatial columns [v, ω] per body; planar [v_x, v_y, ω_z]).  A body-fixed
vector p moves as ṗ = ω × p, so d(p·q)/dt = (ω_p − ω_q)·(p × q); every row is built from that
identity and the chain rule of atan2.  For planar mechanisms the plane itself (z, tilt, v_z,
ω_x, ω_y) is reported separately by :meth:`JointEquations.plane_residuals`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np

from mbh._harness.model.mechanism import Joint, Mechanism
from mbh._harness.model.outputs import body_rotations, wrap_angle

_Z = np.array([0.0, 0.0, 1.0])
_X = np.array([1.0, 0.0, 0.0])
#: Row kinds: a length (joint gaps, distances from a slide line) or an angle.
GAP, ORIENTATION = "gap", "orientation"
_UNIT = {GAP: "m", ORIENTATION: "rad"}


@dataclass(frozen=True)
class _Pose:
    """Body positions and rotations with ground appended as the last body (index −1).

    position : (..., nb + 1, 3); rotation : (..., nb + 1, 3, 3).
    """

    position: np.ndarray
    rotation: np.ndarray

    @classmethod
    def of(cls, position, rotation) -> "_Pose":
        position = np.asarray(position, dtype=float)
        lead = position.shape[:-2]
        ground_r = np.zeros((*lead, 1, 3))
        ground_a = np.broadcast_to(np.eye(3), (*lead, 1, 3, 3))
        return cls(np.concatenate([position, ground_r], axis=-2),
                   np.concatenate([np.asarray(rotation, dtype=float), ground_a], axis=-3))

    def vector(self, body: int, local: np.ndarray) -> np.ndarray:
        """World image (..., 3) of a body-frame vector (or (..., k, 3) of k vectors (k, 3))."""
        rotation = self.rotation[..., body, :, :]
        if local.ndim == 1:
            return np.einsum("...ij,j->...i", rotation, local)
        return np.einsum("...ij,kj->...ki", rotation, local)

    def point(self, body: int, local: np.ndarray) -> np.ndarray:
        """World position (..., 3) of a body-frame point."""
        return self.position[..., body, :] + self.vector(body, local)


def _dot(a, b):
    return np.sum(a * b, axis=-1)


def _atan2_gradient(y, x, grad_y, grad_x):
    """Gradient of atan2(y, x) from the gradients of y and x (last axis: ω components)."""
    return (x[..., None] * grad_y - y[..., None] * grad_x) / (x * x + y * y)[..., None]


class _Block(ABC):
    """A group of rows of one joint (or the driver) between ``body1`` and ``body2``.

    ``offset`` and ``rate`` make a driver row: residual − (offset + rate·t).
    """

    kind = GAP
    suffixes: tuple[str, ...] = ()

    def __init__(self, body1: int, body2: int, offset: float = 0.0, rate: float = 0.0,
                 wrapped: bool = False):
        self.body1, self.body2 = body1, body2
        self.offset, self.rate, self.wrapped = offset, rate, wrapped

    def values(self, pose: _Pose, t) -> np.ndarray:
        """Residuals, shape (..., rows)."""
        raw = self._raw(pose) - (self.offset + self.rate * np.asarray(t, dtype=float))[..., None]
        return wrap_angle(raw) if self.wrapped else raw

    def magnitude(self, pose: _Pose, values: np.ndarray) -> np.ndarray:
        """The group's violation as one number per state (m or rad), shape (...)."""
        return np.linalg.norm(values, axis=-1)

    @abstractmethod
    def _raw(self, pose: _Pose) -> np.ndarray:
        """The rows before the driver offset, shape (..., rows)."""

    @abstractmethod
    def gradients(self, pose: _Pose) -> tuple[np.ndarray, np.ndarray]:
        """Row derivatives with respect to the twists [v, ω] of body 1 and body 2,
        each shape (..., rows, 6)."""


class _PointGap(_Block):
    """d = P₂ − P₁ in world components ``axes``; ḋ = v₂ + ω₂ × s₂ − v₁ − ω₁ × s₁."""

    def __init__(self, body1, body2, point1, point2, axes):
        super().__init__(body1, body2)
        self.point1, self.point2, self.axes = point1, point2, tuple(axes)
        self.suffixes = tuple(f"gap {'xyz'[k]}" for k in self.axes)

    def _raw(self, pose):
        gap = pose.point(self.body2, self.point2) - pose.point(self.body1, self.point1)
        return gap[..., self.axes]

    def gradients(self, pose):
        unit = np.eye(3)[list(self.axes)]                               # (rows, 3)
        arm1 = pose.vector(self.body1, self.point1)[..., None, :]
        arm2 = pose.vector(self.body2, self.point2)[..., None, :]
        lead = arm1.shape[:-2]
        e = np.broadcast_to(unit, (*lead, *unit.shape))
        g1 = np.concatenate([-e, -np.cross(arm1, unit)], axis=-1)     # e·(ω × s) = ω·(s × e)
        g2 = np.concatenate([e, np.cross(arm2, unit)], axis=-1)
        return g1, g2


class _Projection(_Block):
    """e·d for body-1-fixed unit vectors e: distances from a slide line, or the slide itself."""

    def __init__(self, body1, body2, point1, point2, directions, suffixes, offset=0.0, rate=0.0):
        super().__init__(body1, body2, offset, rate)
        self.point1, self.point2 = point1, point2
        self.directions = np.atleast_2d(directions)
        self.suffixes = tuple(suffixes)

    def _gap(self, pose):
        return pose.point(self.body2, self.point2) - pose.point(self.body1, self.point1)

    def _raw(self, pose):
        e = pose.vector(self.body1, self.directions)                    # (..., rows, 3)
        return np.einsum("...ki,...i->...k", e, self._gap(pose))

    def gradients(self, pose):
        e = pose.vector(self.body1, self.directions)
        gap = self._gap(pose)[..., None, :]
        arm1 = pose.vector(self.body1, self.point1)[..., None, :]
        arm2 = pose.vector(self.body2, self.point2)[..., None, :]
        # d(e·d)/dt = ω₁·(e × d) + e·(v₂ + ω₂ × s₂ − v₁ − ω₁ × s₁)
        g1 = np.concatenate([-e, np.cross(e, gap + arm1)], axis=-1)
        g2 = np.concatenate([e, np.cross(arm2, e)], axis=-1)
        return g1, g2


def _angular(g):
    """Pad ω-only gradients (..., rows, 3) with zero velocity columns."""
    return np.concatenate([np.zeros_like(g), g], axis=-1)


class _AxisTilt(_Block):
    """The two projected tilt angles of a₂ away from a₁ (about h₁ and about f₁)."""

    kind = ORIENTATION
    suffixes = ("tilt about normal", "tilt about binormal")

    def __init__(self, body1, body2, axis1, normal1, axis2):
        super().__init__(body1, body2)
        self.axis1, self.normal1, self.axis2 = axis1, normal1, axis2

    def _vectors(self, pose):
        a1 = pose.vector(self.body1, self.axis1)
        h1 = pose.vector(self.body1, self.normal1)
        return a1, h1, np.cross(a1, h1), pose.vector(self.body2, self.axis2)

    def _raw(self, pose):
        a1, h1, f1, a2 = self._vectors(pose)
        x = _dot(a1, a2)
        return np.stack([np.arctan2(-_dot(f1, a2), x), np.arctan2(_dot(h1, a2), x)], axis=-1)

    def magnitude(self, pose, values):
        """The angle between the two axes, rad."""
        a1, _, _, a2 = self._vectors(pose)
        return np.arctan2(np.linalg.norm(np.cross(a1, a2), axis=-1), _dot(a1, a2))

    def gradients(self, pose):
        a1, h1, f1, a2 = self._vectors(pose)
        x, grad_x = _dot(a1, a2), np.cross(a1, a2)            # gradient w.r.t. ω₁ (ω₂: minus)
        rows = [_atan2_gradient(_dot(-f1, a2), x, np.cross(-f1, a2), grad_x),
                _atan2_gradient(_dot(h1, a2), x, np.cross(h1, a2), grad_x)]
        g = np.stack(rows, axis=-2)
        return _angular(g), _angular(-g)


class _Twist(_Block):
    """Rotation of body 2 about body 1's axis: atan2(f₁·h₂, h₁·h₂), wrapped."""

    kind = ORIENTATION

    def __init__(self, body1, body2, axis1, normal1, normal2, suffix, offset=0.0, rate=0.0):
        super().__init__(body1, body2, offset, rate, wrapped=True)
        self.axis1, self.normal1, self.normal2 = axis1, normal1, normal2
        self.suffixes = (suffix,)

    def _vectors(self, pose):
        a1 = pose.vector(self.body1, self.axis1)
        h1 = pose.vector(self.body1, self.normal1)
        return h1, np.cross(a1, h1), pose.vector(self.body2, self.normal2)

    def _raw(self, pose):
        h1, f1, h2 = self._vectors(pose)
        return np.arctan2(_dot(f1, h2), _dot(h1, h2))[..., None]

    def magnitude(self, pose, values):
        return np.abs(values[..., 0])

    def gradients(self, pose):
        h1, f1, h2 = self._vectors(pose)
        g = _atan2_gradient(_dot(f1, h2), _dot(h1, h2), np.cross(f1, h2), np.cross(h1, h2))
        return _angular(g[..., None, :]), _angular(-g[..., None, :])


class _CrossAxes(_Block):
    """asin(a₁·a₂) written as atan2(a₁·a₂, |a₁ × a₂|): how far the cross axes are from 90°."""

    kind = ORIENTATION
    suffixes = ("cross axes",)

    def __init__(self, body1, body2, axis1, axis2):
        super().__init__(body1, body2)
        self.axis1, self.axis2 = axis1, axis2

    def _raw(self, pose):
        a1, a2 = pose.vector(self.body1, self.axis1), pose.vector(self.body2, self.axis2)
        return np.arctan2(_dot(a1, a2), np.linalg.norm(np.cross(a1, a2), axis=-1))[..., None]

    def gradients(self, pose):
        a1, a2 = pose.vector(self.body1, self.axis1), pose.vector(self.body2, self.axis2)
        cross = np.cross(a1, a2)
        # d asin(c) = (ω₁ − ω₂)·(a₁ × a₂) / √(1 − c²), and √(1 − c²) = |a₁ × a₂| for unit axes
        g = (cross / np.linalg.norm(cross, axis=-1, keepdims=True))[..., None, :]
        return _angular(g), _angular(-g)


class _PlanarAngle(_Block):
    """φ₂ − φ₁ − offset wrapped, φ = atan2(x_y, x_x) of the body's x axis x = A e_x."""

    kind = ORIENTATION

    def __init__(self, body1, body2, suffix, offset=0.0, rate=0.0):
        super().__init__(body1, body2, offset, rate, wrapped=True)
        self.suffixes = (suffix,)

    @staticmethod
    def _angle(pose, body):
        x = pose.vector(body, _X)
        return np.arctan2(x[..., 1], x[..., 0])

    @staticmethod
    def _gradient(pose, body):
        x = pose.vector(body, _X)
        # dφ = ω·(x_x (x × e_y) − x_y (x × e_x)) / (x_x² + x_y²)
        grad = _atan2_gradient(x[..., 1], x[..., 0], np.cross(x, np.eye(3)[1]), np.cross(x, _X))
        return _angular(grad[..., None, :])

    def _raw(self, pose):
        return (self._angle(pose, self.body2) - self._angle(pose, self.body1))[..., None]

    def magnitude(self, pose, values):
        return np.abs(values[..., 0])

    def gradients(self, pose):
        return -self._gradient(pose, self.body1), self._gradient(pose, self.body2)


def _reference_pose(mech: Mechanism) -> _Pose:
    return _Pose.of(np.array([b.position for b in mech.bodies]),
                    np.array([b.rotation for b in mech.bodies]))


def _reference_value(mech: Mechanism, block: _Block) -> float:
    """A one-row block's raw value in the reference configuration (rad or m)."""
    return float(block._raw(_reference_pose(mech))[0])


def _joint_blocks(mech: Mechanism, joint: Joint) -> list[_Block]:
    """The rows of one joint (see the module table)."""
    i, j = mech.body_index(joint.body1), mech.body_index(joint.body2)
    if mech.planar:
        if joint.type == "revolute":
            return [_PointGap(i, j, joint.point1, joint.point2, axes=(0, 1))]
        reference = _reference_value(mech, _PlanarAngle(i, j, ""))
        return [_PlanarAngle(i, j, "relative angle", offset=reference),
                _Projection(i, j, joint.point1, joint.point2, np.cross(_Z, joint.axis1),
                            ("off axis",))]
    blocks: list[_Block] = []
    if joint.type in ("spherical", "universal", "revolute"):
        blocks.append(_PointGap(i, j, joint.point1, joint.point2, axes=(0, 1, 2)))
    if joint.type == "universal":
        blocks.append(_CrossAxes(i, j, joint.axis1, joint.axis2))
    if joint.type in ("revolute", "cylindrical", "translational", "prismatic"):
        blocks.append(_AxisTilt(i, j, joint.axis1, joint.normal1, joint.axis2))
    if joint.type in ("cylindrical", "translational", "prismatic"):
        binormal = np.cross(joint.axis1, joint.normal1)
        blocks.append(_Projection(i, j, joint.point1, joint.point2, [joint.normal1, binormal],
                                  ("off axis along normal", "off axis along binormal")))
    if joint.type in ("translational", "prismatic"):
        blocks.append(_Twist(i, j, joint.axis1, joint.normal1, joint.normal2, "twist about axis"))
    return blocks


def _coordinate_block(mech: Mechanism, joint: Joint, value: float = 0.0,
                      rate: float = 0.0) -> _Block:
    """One row: the joint's coordinate (measured from the reference configuration) minus
    value + rate·t — the driver row, or a prescribed joint rate's row.

    Raises
    ------
    ValueError
        For a joint type without a single coordinate (spherical, universal).
    """
    i, j = mech.body_index(joint.body1), mech.body_index(joint.body2)
    if joint.type in ("prismatic", "translational"):
        reference = _reference_value(mech, _Projection(i, j, joint.point1, joint.point2,
                                                       joint.axis1, ("slide",)))
        return _Projection(i, j, joint.point1, joint.point2, joint.axis1, ("slide",),
                           offset=reference + value, rate=rate)
    if joint.type == "revolute" and mech.planar:
        reference = _reference_value(mech, _PlanarAngle(i, j, ""))
        return _PlanarAngle(i, j, "angle", offset=reference + value, rate=rate)
    if joint.type in ("revolute", "cylindrical"):
        return _Twist(i, j, joint.axis1, joint.normal1, joint.normal2, "angle", value, rate)
    raise ValueError(f"joint {joint.name!r} is {joint.type}, which has no single coordinate")


class JointEquations:
    """Residuals, their rates and their Jacobian for a mechanism's joints (and driver).

    Parameters
    ----------
    mech : Mechanism
    with_driver : bool
        Append the driver row (the last row).
    drive : (value, rate), optional
        The driver's coordinate value (rad or m, from the reference configuration) and rate;
        default ``mech.initial``'s.
    coordinates : tuple of str
        Joints whose coordinate rows (from the reference configuration, value 0, rate 0) follow the
        driver row: the rows of prescribed joint rates.

    Attributes
    ----------
    labels : tuple of str
        One per row, e.g. ``"joint B (revolute): gap x"``, ``"driver O (revolute): angle"``.
    units : tuple of str
        ``"m"`` or ``"rad"`` per row (their rates are m/s and rad/s).
    kinds : tuple of str
        :data:`GAP` or :data:`ORIENTATION` per row.
    rates : ndarray, shape (m,)
        The prescribed rate of each row (the driver's rate on its row, zero elsewhere).
    n_joint_rows : int
        The first ``n_joint_rows`` rows are the joints'; the driver and coordinate rows follow.
    twist_size : int
        Columns per body in :meth:`jacobian`: 6 ([v, ω], spatial) or 3 ([v_x, v_y, ω_z], planar).
    """

    def __init__(self, mech: Mechanism, with_driver: bool = False, drive=None,
                 coordinates: tuple[str, ...] = ()):
        self.mech = mech
        self.n_bodies = len(mech.bodies)
        self.twist_size = 3 if mech.planar else 6
        self._columns = twist_columns(mech.planar)
        entries = [(f"joint {joint.name} ({joint.type})", block)
                   for joint in mech.joints for block in _joint_blocks(mech, joint)]
        self.n_joint_rows = sum(len(block.suffixes) for _, block in entries)
        if with_driver:
            value, rate = (mech.initial.value, mech.initial.rate) if drive is None else drive
            driver = mech.joint(mech.initial.driver)
            entries.append((f"driver {driver.name} ({driver.type})",
                            _coordinate_block(mech, driver, value, rate)))
        for name in coordinates:
            joint = mech.joint(name)
            entries.append((f"coordinate {joint.name} ({joint.type})",
                            _coordinate_block(mech, joint)))
        self._blocks = [block for _, block in entries]
        self.labels = tuple(f"{prefix}: {suffix}" for prefix, block in entries
                            for suffix in block.suffixes)
        self.kinds = tuple(block.kind for block in self._blocks for _ in block.suffixes)
        self.units = tuple(_UNIT[kind] for kind in self.kinds)
        self.rates = np.array([block.rate for block in self._blocks for _ in block.suffixes])
        self.m = len(self.labels)

    # -- evaluation ---------------------------------------------------------------------------
    def _pose(self, position, quaternion) -> _Pose:
        return _Pose.of(position, body_rotations(quaternion))

    def residuals(self, position, quaternion, t=0.0) -> np.ndarray:
        """Residuals, shape (..., m), m or rad (see :attr:`units`).

        Parameters
        ----------
        position : ndarray, shape (..., n_bodies, 3)
            Centre-of-mass positions, m.
        quaternion : ndarray, shape (..., n_bodies, 4)
            Orientations, scalar first.
        t : float or ndarray broadcastable to the leading shape
            Time, s (enters the driver row only).
        """
        pose = self._pose(position, quaternion)
        lead = pose.position.shape[:-2]
        if not self._blocks:
            return np.zeros((*lead, 0))
        return np.concatenate([np.broadcast_to(b.values(pose, t), (*lead, len(b.suffixes)))
                               for b in self._blocks], axis=-1)

    def _gradients(self, pose: _Pose) -> list[tuple[_Block, np.ndarray, np.ndarray]]:
        return [(block, *block.gradients(pose)) for block in self._blocks]

    def jacobian(self, position, quaternion) -> np.ndarray:
        """∂(rows)/∂(body twists), shape (..., m, twist_size·n_bodies).

        Spatial columns per body are [v, ω] (world axes), planar [v_x, v_y, ω_z].
        """
        pose = self._pose(position, quaternion)
        lead = pose.position.shape[:-2]
        k = self.twist_size
        matrix = np.zeros((*lead, self.m, k * self.n_bodies))
        row = 0
        for block, g1, g2 in self._gradients(pose):
            rows = slice(row, row + len(block.suffixes))
            for body, g in ((block.body1, g1), (block.body2, g2)):
                if body >= 0:  # ground (−1) has no columns
                    matrix[..., rows, k * body:k * body + k] += g[..., self._columns]
            row = rows.stop
        return matrix

    def velocity_residuals(self, position, quaternion, velocity, angular_velocity) -> np.ndarray:
        """Time derivatives of the rows, shape (..., m), m/s or rad/s.

        Equal to ``jacobian @ twist`` minus the driver's rate.  For planar mechanisms this is the
        exact derivative of the planar rows for any spatial twist (ω_x, ω_y enter through the
        tilt of a body's x axis), so it equals the planar Jacobian times [v_x, v_y, ω_z] for
        states in the plane.
        """
        pose = self._pose(position, quaternion)
        twist = np.concatenate([np.asarray(velocity, dtype=float),
                                np.asarray(angular_velocity, dtype=float)], axis=-1)
        lead = pose.position.shape[:-2]
        twist = np.concatenate([twist, np.zeros((*lead, 1, 6))], axis=-2)  # ground at rest
        if not self._blocks:
            return np.zeros((*lead, 0))
        parts = [np.einsum("...rc,...c->...r", g1, twist[..., block.body1, :])
                 + np.einsum("...rc,...c->...r", g2, twist[..., block.body2, :])
                 for block, g1, g2 in self._gradients(pose)]
        return np.concatenate(parts, axis=-1) - self.rates

    # -- per-joint magnitudes and the plane ------------------------------------------------
    def group_magnitudes(self, position, quaternion, velocity=None, angular_velocity=None) -> dict:
        """One violation number per row group (a joint's gap, its distance from the slide line,
        its axis tilt, ...), joint rows only.

        Returns
        -------
        dict
            ``"gap_m"`` (..., n_gap_groups): distances between points that should coincide and
            from slide lines, m.  ``"orientation_rad"`` (..., n_orientation_groups): angles (the
            axis tilt is the angle between the two axes).  With velocities also
            ``"velocity_m_s"`` and ``"angular_velocity_rad_s"``: the Euclidean norm of each
            group's rates.
        """
        pose = self._pose(position, quaternion)
        lead = pose.position.shape[:-2]
        rates = None
        if velocity is not None:
            rates = self.velocity_residuals(position, quaternion, velocity, angular_velocity)
        result = {"gap_m": [], "orientation_rad": [], "velocity_m_s": [],
                  "angular_velocity_rad_s": []}
        row = 0
        for block in self._blocks:
            rows = slice(row, row + len(block.suffixes))
            row = rows.stop
            if rows.stop > self.n_joint_rows:
                break  # the driver and prescribed rows are not violations
            gap = block.kind == GAP
            result["gap_m" if gap else "orientation_rad"].append(
                block.magnitude(pose, block.values(pose, 0.0)))
            if rates is not None:
                result["velocity_m_s" if gap else "angular_velocity_rad_s"].append(
                    np.linalg.norm(rates[..., rows], axis=-1))
        keys = list(result) if rates is not None else ["gap_m", "orientation_rad"]
        return {key: np.stack(result[key], axis=-1) if result[key] else np.zeros((*lead, 0))
                for key in keys}

    @staticmethod
    def plane_residuals(position, quaternion, velocity=None, angular_velocity=None) -> dict:
        """Departure from the x–y plane of a planar mechanism's bodies.

        Returns
        -------
        dict of ndarray, each shape (..., n_bodies)
            ``"out_of_plane_m"``: |z| of each centre of mass; ``"tilt_rad"``: angle between the
            body z axis and world z; with velocities also ``"out_of_plane_velocity_m_s"``: |v_z|,
            and ``"out_of_plane_angular_velocity_rad_s"``: |(ω_x, ω_y)|.
        """
        z_axis = body_rotations(quaternion)[..., :, 2]
        result = {
            "out_of_plane_m": np.abs(np.asarray(position)[..., 2]),
            "tilt_rad": np.arctan2(np.linalg.norm(z_axis[..., :2], axis=-1), z_axis[..., 2]),
        }
        if velocity is not None:
            result["out_of_plane_velocity_m_s"] = np.abs(np.asarray(velocity)[..., 2])
            result["out_of_plane_angular_velocity_rad_s"] = np.linalg.norm(
                np.asarray(angular_velocity)[..., :2], axis=-1)
        return result


def twist_columns(planar: bool) -> list[int]:
    """Which of a body's spatial twist components [v, ω] the Jacobians' columns hold: all six,
    or [v_x, v_y, ω_z] for a planar mechanism."""
    return [0, 1, 5] if planar else list(range(6))


def body_twists(twist: np.ndarray, planar: bool) -> np.ndarray:
    """Body twists [v, ω], shape (n_bodies, 6), m/s and rad/s, from a vector over the Jacobians'
    columns (:func:`twist_columns` per body; the missing planar components are zero)."""
    columns = twist_columns(planar)
    rows = np.asarray(twist, dtype=float).reshape(-1, len(columns))
    spatial = np.zeros((rows.shape[0], 6))
    spatial[:, columns] = rows
    return spatial


def twist_vector(linear: np.ndarray, angular: np.ndarray, planar: bool) -> np.ndarray:
    """The inverse of :func:`body_twists`: linear and angular velocities (n_bodies, 3) each to
    the vector over the Jacobians' columns, shape (n_bodies · len(twist_columns),)."""
    spatial = np.concatenate([np.asarray(linear, dtype=float),
                              np.asarray(angular, dtype=float)], axis=-1)
    return spatial[:, twist_columns(planar)].ravel()


def point_velocity_jacobian(mech: Mechanism, body: str, point: np.ndarray, position,
                            quaternion) -> np.ndarray:
    """∂(world velocity of a body point)/∂(body twists), shape (3, twist_size·n_bodies).

    The point ``point`` (body frame, m) of ``body`` moves at v + ω × s, s = A·point, so row k
    holds e_k on the body's v columns and s × e_k on its ω columns (planar: [v_x, v_y, ω_z]).
    """
    pose = _Pose.of(position, body_rotations(quaternion))
    index = mech.body_index(body)
    arm = pose.vector(index, np.asarray(point, dtype=float))
    block = np.concatenate([np.eye(3), np.cross(arm[None, :], np.eye(3))], axis=-1)
    columns = twist_columns(mech.planar)
    k = len(columns)
    matrix = np.zeros((3, k * len(mech.bodies)))
    matrix[:, k * index:k * index + k] = block[:, columns]
    return matrix
