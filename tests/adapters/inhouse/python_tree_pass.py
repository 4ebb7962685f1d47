"""The Python pass over a spanning tree's moves, kept as the test oracle of the compiled one
(:func:`mbh._adapters.inhouse.bodies.tree_pass.tree_pass`): the joint-coordinate formulation's
first implementation, numpy on one frame at a time, with the same equations
(:mod:`mbh._adapters.inhouse.bodies.tree_kinematics`) in numpy's order of operations.
"""

from __future__ import annotations

import numpy as np


def _cross(a, b):
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])


def _product(a, b):
    a0, a1, a2, a3 = a
    b0, b1, b2, b3 = b
    return np.array([a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3,
                     a0 * b1 + b0 * a1 + a2 * b3 - a3 * b2,
                     a0 * b2 + b0 * a2 + a3 * b1 - a1 * b3,
                     a0 * b3 + b0 * a3 + a1 * b2 - a2 * b1])


def _turn(axis, angle):
    return np.array([np.cos(0.5 * angle), *(np.sin(0.5 * angle) * axis)])


def _matrix(e):
    e0, e1, e2, e3 = e
    a = 2.0 * e0 * e0 - 1.0
    return np.array([[a + 2.0 * e1 * e1, 2.0 * (e1 * e2 - e0 * e3), 2.0 * (e1 * e3 + e0 * e2)],
                     [2.0 * (e2 * e1 + e0 * e3), a + 2.0 * e2 * e2, 2.0 * (e2 * e3 - e0 * e1)],
                     [2.0 * (e3 * e1 - e0 * e2), 2.0 * (e3 * e2 + e0 * e1), a + 2.0 * e3 * e3]])


def _skew(v):
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _rate_map(e):
    return np.vstack([-e[1:], e[0] * np.eye(3) - _skew(e[1:])])


def python_tree_pass(kinematics, theta, rate):
    """(g(θ) (n,), B (n, n_θ), Ḃθ̇ (n,)) of a
    :class:`~mbh._adapters.inhouse.bodies.tree_kinematics.TreeKinematics` at θ, θ̇ (n_θ,)."""
    moves, n = kinematics.moves, kinematics.n
    ground = (np.array([1.0, 0.0, 0.0, 0.0]), np.eye(3), np.zeros(3), 0.0,
              np.zeros((3, n)), np.zeros((3, n)), np.zeros(3), np.zeros(3))
    frames: list = [None] * moves.n_frames
    for move in moves.moves:
        e_p, a_p, r_p, phi_p, jw_p, jv_p, al_p, ac_p = (frames[move.parent] if move.parent >= 0
                                                        else ground)
        k, sign = move.coordinate, move.sign
        axis_w = a_p @ move.axis
        if move.kind == "turn":
            e = _product(_product(e_p, _turn(move.axis, sign * theta[k])), move.offset)
            d_p = a_p @ move.at_parent
        else:
            e = _product(e_p, move.offset)
            d_p = a_p @ move.at_parent + sign * theta[k] * axis_w
        a = _matrix(e)
        d_c = a @ move.at_child
        r = r_p + d_p - d_c
        phi = phi_p + (sign * theta[k] * move.axis[2] if move.kind == "turn" else 0.0) \
            + 2.0 * float(np.arctan2(move.offset[3], move.offset[0]))
        jw = jw_p.copy()
        if move.kind == "turn":
            jw[:, k] += sign * axis_w
        jv = jv_p - _skew(d_p) @ jw_p + _skew(d_c) @ jw
        if move.kind == "slide":
            jv[:, k] += sign * axis_w
        w_p, w = jw_p @ rate, jw @ rate
        alpha = al_p + (_cross(w_p, sign * rate[k] * axis_w) if move.kind == "turn" else 0.0)
        acc = (ac_p + _cross(al_p, d_p) + _cross(w_p, _cross(w_p, d_p))
               - _cross(alpha, d_c) - _cross(w, _cross(w, d_c)))
        if move.kind == "slide":
            acc = acc + 2.0 * sign * rate[k] * _cross(w_p, axis_w)
        frames[move.child] = (e, a, r, phi, jw, jv, alpha, acc)
    nc, size = kinematics.nc, kinematics.n_absolute
    q, b, bias_q = np.empty(size), np.empty((size, n)), np.empty(size)
    for index, (e, _, r, phi, jw, jv, alpha, acc) in enumerate(frames[:kinematics.n_bodies]):
        k = index * nc
        if kinematics.planar:
            q[k:k + 3] = r[0], r[1], phi + kinematics.turns[index]
            b[k:k + 2], b[k + 2] = jv[:2], jw[2]
            bias_q[k:k + 3] = acc[0], acc[1], alpha[2]
            continue
        sign = kinematics.signs[index]
        q[k:k + 3], q[k + 3:k + 7] = r, sign * e
        rate_map = 0.5 * sign * _rate_map(e)
        b[k:k + 3], b[k + 3:k + 7] = jv, rate_map @ jw
        omega = jw @ rate
        bias_q[k:k + 3] = acc
        bias_q[k + 3:k + 7] = rate_map @ alpha - 0.25 * sign * (omega @ omega) * e
    return q, b, bias_q
