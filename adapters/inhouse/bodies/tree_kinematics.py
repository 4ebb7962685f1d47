"""Forward kinematics of the spanning tree in joint coordinates: q = g(θ), B = ∂g/∂θ and the bias
Ḃθ̇, in the absolute layout of :mod:`.constraints` (planar x, y, φ; spatial R and Euler
parameters, scalar first).

One pass over the moves of :mod:`.tree_moves` (parents first; compiled, :mod:`.tree_pass`, one
call for g, B and Ḃθ̇ together) carries, per frame, the orientation
(a quaternion e, A = A(e)), the origin r, and the velocity Jacobians J_ω, J_v (3, n_θ) with
ω = J_ω θ̇ and ṙ = J_v θ̇ in world axes.  With d_P = A_P p (+ σ s A_P u for a slide) and
d_C = A_C c:

    J_ω,C = J_ω,P + σ u_w e_k                   (turn; u_w = A_P u, e_k the coordinate's column)
    J_v,C = J_v,P − [d_P]× J_ω,P + [d_C]× J_ω,C (+ σ u_w e_k for a slide)

the spatial form of Arczewski's Ω = ω₀·1 + Pᵀω (1995, eq. 3 with ω₀ = 0, the column of a joint
reaching the bodies its path-matrix row marks, signed by P) extended to the velocities of the
bodies' origins.  The bias (the accelerations at θ̈ = 0, Ḃθ̇) follows the same pass:

    α_C = α_P + ω_P × σθ̇_k u_w  (turn),      α_C = α_P  (slide)
    a_C = a_P + α_P × d_P + ω_P × (ω_P × d_P) + 2σṡ_k ω_P × u_w (slide) − α_C × d_C − ω_C × (ω_C × d_C)

Euler parameters: ė = ½ L(e) ω with L(e) = [−ēᵀ; e₀I − [ē]×] ((0, ω) ⊗ e, world ω), so
B_e = ½ L(e) J_ω and the bias ë = ½ L(e) α − ¼|ω|² e.  Planar: φ̇ = ω_z, the bias φ̈ = α_z; φ is
carried as a sum of angles (never read back from a matrix), so it does not wrap.  Every column of
B is analytic (tests/adapters/inhouse/test_joint_coordinates.py checks B and Ḃθ̇ against central
differences of g, and the compiled pass against the first, Python one kept there as its oracle).
This class holds the pass's table and the start's inverse kinematics (θ of an absolute q), which
runs once per run in Python.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from mbh._adapters.inhouse.bodies.bodykin import PLANAR_NC, SPATIAL_NC
from mbh._adapters.inhouse.bodies.tree_pass import tree_pass, tree_table
from mbh._adapters.inhouse.bodies.tree_moves import (TREE_JOINT_COORDINATES, TreeMoves,
                                                     tree_moves, tree_of)
from mbh._harness.model.mechanism import Mechanism

#: Largest |g(θ₀) − q₀| accepted at the start (m, rad, Euler parameters): the common start meets
#: the tree joints' equations to ~1e-15, and the inverse kinematics is exact up to round-off.
START_MATCH = 1e-9


def _planar_angle(e: np.ndarray) -> float:
    """The angle about z of a quaternion that turns about ±z (rad, in (−2π, 2π])."""
    return 2.0 * float(np.arctan2(e[3], e[0]))


class TreeKinematics:
    """q = g(θ), B(θ) and Ḃθ̇ of a mechanism's spanning tree.

    Parameters
    ----------
    mech : Mechanism
        Every tree joint of its tree (:func:`~.tree_moves.tree_of`) must have moves.
    q0 : ndarray, shape (n,)
        The common start in absolute coordinates: fixes the per-body sign of the Euler
        parameters and the planar angles' turns (multiples of 2π) that g(θ) reproduces.

    Attributes
    ----------
    moves : TreeMoves
    n : int
        Number of joint coordinates n_θ.
    n_absolute : int
        Length of q.
    theta0 : ndarray, shape (n_θ,)
        The joint coordinates of q0 (:meth:`coordinates_of`).
    """

    def __init__(self, mech: Mechanism, q0: np.ndarray):
        self.mech = mech
        self.moves: TreeMoves = tree_moves(mech, tree_of(mech))
        self.planar = mech.planar
        self.nc = PLANAR_NC if self.planar else SPATIAL_NC
        self.n_bodies = len(mech.bodies)
        self.n = self.moves.n_coordinates
        self.n_absolute = self.n_bodies * self.nc
        self._signs = np.ones(self.n_bodies)
        self._turns = np.zeros(self.n_bodies)
        self._set_table()
        self.theta0 = self.coordinates_of(q0)
        q = self.positions(self.theta0)
        if self.planar:
            self._turns = np.round((q0 - q)[2::3] / (2.0 * np.pi)) * 2.0 * np.pi
        else:
            e, e_start = q.reshape(-1, 7)[:, 3:], q0.reshape(-1, 7)[:, 3:]
            self._signs = np.where(np.sum(e * e_start, axis=1) < 0.0, -1.0, 1.0)
        self._set_table()
        gap = float(np.abs(self.positions(self.theta0) - q0).max(initial=0.0))
        if not gap <= START_MATCH:
            raise ValueError(f"mechanism {mech.name!r}: the tree's kinematics reproduce the "
                             f"common start only to {gap:.3g} (> {START_MATCH:g}); its tree "
                             "joints are not assembled there")

    # -- the pass over the moves (compiled: :mod:`.tree_pass`) ---------------------------------
    @property
    def turns(self) -> np.ndarray:
        """Multiples of 2π added to each body's planar angle (b,), rad."""
        return self._turns

    @property
    def signs(self) -> np.ndarray:
        """±1 on each body's Euler parameters (b,)."""
        return self._signs

    def _set_table(self) -> None:
        """The flat table of :func:`~.tree_pass.tree_pass` for the current turns and signs."""
        self.table = tree_table(self.moves, self._turns, self._signs, self.planar)

    def positions(self, theta: np.ndarray) -> np.ndarray:
        """q = g(θ), shape (n,)."""
        theta = np.asarray(theta, dtype=float)
        return tree_pass(theta, np.zeros(self.n), self.table)[0]

    def evaluate(self, theta: np.ndarray, rate: np.ndarray | None = None):
        """g(θ) (n,), B(θ) (n, n_θ) and, given θ̇ (n_θ,), the bias Ḃθ̇ (n,), else None.

        Units: q in m and rad (planar) or m and Euler parameters; B's columns per unit
        coordinate (rad or m); Ḃθ̇ in m/s², rad/s² or 1/s².
        """
        theta = np.asarray(theta, dtype=float)
        given = rate is not None
        rate = np.asarray(rate, dtype=float) if given else np.zeros(self.n)
        q, b, bias = tree_pass(theta, rate, self.table)
        return q, b, (bias if given else None)

    # -- from absolute coordinates ----------------------------------------------------------------
    def coordinates_of(self, q: np.ndarray) -> np.ndarray:
        """θ of a configuration q (n,) whose tree joints are assembled: each joint's coordinates
        from the relative pose of its two bodies (the inverse of :meth:`positions`)."""
        theta = np.zeros(self.n)
        mech, nc = self.mech, self.nc
        done = set()
        for move in self.moves.moves:
            if move.joint in done:
                continue
            done.add(move.joint)
            joint = mech.joint(move.joint)
            first = min(m.coordinate for m in self.moves.moves if m.joint == move.joint)
            theta[first:first + TREE_JOINT_COORDINATES[joint.type]] = \
                self._joint_coordinates(joint, q, nc)
        return theta

    def _pose(self, q: np.ndarray, body: str):
        """(Rotation, origin, planar angle) of a body in q (ground: identity, 0, 0)."""
        index = self.mech.body_index(body)
        if index < 0:
            return Rotation.identity(), np.zeros(3), 0.0
        block = q[index * self.nc:(index + 1) * self.nc]
        if self.planar:
            return (Rotation.from_euler("z", block[2]), np.array([block[0], block[1], 0.0]),
                    float(block[2]))
        return Rotation.from_quat(block[3:], scalar_first=True), block[:3], 0.0

    def _joint_coordinates(self, joint, q: np.ndarray, nc: int) -> list[float]:
        """The coordinates of one joint at q (angles from the relative rotation about the axis;
        planar angles as the exact difference of the bodies' φ, so g reproduces them)."""
        rot1, r1, phi1 = self._pose(q, joint.body1)
        rot2, r2, phi2 = self._pose(q, joint.body2)
        ref1, ref2 = (Rotation.identity() if b == "ground" else Rotation.from_matrix(
            self.mech.bodies[self.mech.body_index(b)].rotation) for b in (joint.body1, joint.body2))
        relative0 = ref1.inv() * ref2
        a1 = np.asarray(joint.axis1, dtype=float)
        slide = float(a1 @ (rot1.inv().apply(r2 + rot2.apply(joint.point2) - r1) - joint.point1))
        turned = rot1.inv() * rot2 * relative0.inv()  # Rot(a1, θ) (revolute, cylindrical)
        if joint.type in ("prismatic", "translational"):
            return [slide]
        if joint.type == "universal":
            crossed = relative0.apply(np.asarray(joint.axis2, dtype=float))
            moved = turned.apply(crossed)
            first = float(np.arctan2(a1 @ np.cross(crossed, moved), crossed @ moved))
            rest = Rotation.from_rotvec(first * a1).inv() * turned
            return [first, _angle_about(rest, crossed)]
        if self.planar:
            angle = (phi2 - phi1 - _planar_angle(relative0.as_quat(scalar_first=True))) * a1[2]
        else:
            angle = _angle_about(turned, a1)
        return [angle, slide] if joint.type == "cylindrical" else [angle]

    def rates_of(self, theta: np.ndarray, v: np.ndarray) -> np.ndarray:
        """θ̇ with B(θ) θ̇ = q̇ (least squares: exact for a q̇ the tree can make), shape (n_θ,)."""
        _, b, _ = self.evaluate(theta)
        return np.linalg.lstsq(b, v, rcond=None)[0]


def _angle_about(rotation: Rotation, axis: np.ndarray) -> float:
    """The angle (rad) of a rotation about the unit ``axis`` it turns about."""
    vector = rotation.as_rotvec()
    return float(axis @ vector) if vector @ vector > 0 else 0.0
