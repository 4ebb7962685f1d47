"""The compiled pass over a spanning tree's moves: q = g(θ), B = ∂g/∂θ and the bias Ḃθ̇ in one
call, over the flat table :func:`tree_table` makes once from :class:`~.tree_moves.TreeMoves`.

The equations are those of :mod:`.tree_kinematics` (its docstring: Arczewski 1995, eq. 3,
extended to the bodies' origins; Euler parameters ė = ½ L(e) ω), in the same order of
operations, so the pass returns the Python pass's numbers to round-off (the sums of the 3 × 3
products are written out instead of going through BLAS).  Per frame (bodies, then the massless
frames of two-coordinate joints, then ground as the last row, where a parent index of −1 lands)
it keeps the quaternion e (4,), A(e) (3, 3), the origin r (3,), the planar angle φ, the velocity
Jacobians J_ω, J_v (3, n_θ) and the bias accelerations α, a (3,), all in world axes.

Table (:func:`tree_table`), one row per move, parents before children:

=============  ==========  ===========================================================
array          shape       meaning
=============  ==========  ===========================================================
``parent``     (k,) int    parent frame, −1 ground
``child``      (k,) int    child frame
``slide``      (k,) int    1 for a slide along the axis, 0 for a turn about it
``coordinate`` (k,) int    index of the move's coordinate in θ
``sign``       (k,)        σ = ±1
``axis``       (k, 3)      unit axis u in the parent's frame
``at_parent``  (k, 3)      joint point in the parent's frame, m
``at_child``   (k, 3)      joint point in the child's frame, m
``offset``     (k, 4)      R₀ as a unit quaternion, scalar first
``angle``      (k,)        R₀'s angle about z (planar), rad
=============  ==========  ===========================================================

followed by the per-body ``turns`` (b,) (multiples of 2π added to planar angles, rad) and
``signs`` (b,) (±1 on the Euler parameters), the number of frames and the planar flag.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from mbh._adapters.inhouse.bodies.bodykin import PLANAR_NC, SPATIAL_NC


def tree_table(moves, turns: np.ndarray, signs: np.ndarray, planar: bool) -> tuple:
    """The flat arguments of :func:`tree_pass` (module docstring) from a
    :class:`~.tree_moves.TreeMoves`, the per-body ``turns`` (b,) and ``signs`` (b,)."""
    rows = moves.moves

    def stack(values, dtype, shape):
        return np.ascontiguousarray(np.array(values, dtype=dtype).reshape(shape))
    count = len(rows)
    return (stack([m.parent for m in rows], np.int64, (count,)),
            stack([m.child for m in rows], np.int64, (count,)),
            stack([m.kind == "slide" for m in rows], np.int64, (count,)),
            stack([m.coordinate for m in rows], np.int64, (count,)),
            stack([m.sign for m in rows], float, (count,)),
            stack([m.axis for m in rows], float, (count, 3)),
            stack([m.at_parent for m in rows], float, (count, 3)),
            stack([m.at_child for m in rows], float, (count, 3)),
            stack([m.offset for m in rows], float, (count, 4)),
            stack([2.0 * np.arctan2(m.offset[3], m.offset[0]) for m in rows], float, (count,)),
            np.ascontiguousarray(turns, dtype=float), np.ascontiguousarray(signs, dtype=float),
            moves.n_frames, planar)


@njit(cache=True)
def _times(a, x):
    """A x of a (3, 3) array and a (3,) array, a tuple (3) (BLAS's order of the sums)."""
    return (a[0, 0] * x[0] + a[0, 1] * x[1] + a[0, 2] * x[2],
            a[1, 0] * x[0] + a[1, 1] * x[1] + a[1, 2] * x[2],
            a[2, 0] * x[0] + a[2, 1] * x[1] + a[2, 2] * x[2])


@njit(cache=True)
def _cross(a, b):
    """a × b of two 3-sequences, a tuple (3)."""
    return a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]


@njit(cache=True)
def _product(a, b):
    """Quaternion product a ⊗ b of two 4-sequences, scalar first, a tuple (4)."""
    return (a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
            a[0] * b[1] + b[0] * a[1] + a[2] * b[3] - a[3] * b[2],
            a[0] * b[2] + b[0] * a[2] + a[3] * b[1] - a[1] * b[3],
            a[0] * b[3] + b[0] * a[3] + a[1] * b[2] - a[2] * b[1])


@njit(cache=True)
def _matrix_into(out, e):
    """out (3, 3) = A(e) of a unit quaternion (4,), scalar first (Rouvinen 2003, eq. 5)."""
    e0, e1, e2, e3 = e[0], e[1], e[2], e[3]
    a = 2.0 * e0 * e0 - 1.0
    out[0, 0], out[0, 1], out[0, 2] = a + 2.0 * e1 * e1, 2.0 * (e1 * e2 - e0 * e3), \
        2.0 * (e1 * e3 + e0 * e2)
    out[1, 0], out[1, 1], out[1, 2] = 2.0 * (e2 * e1 + e0 * e3), a + 2.0 * e2 * e2, \
        2.0 * (e2 * e3 - e0 * e1)
    out[2, 0], out[2, 1], out[2, 2] = 2.0 * (e3 * e1 - e0 * e2), 2.0 * (e3 * e2 + e0 * e1), \
        a + 2.0 * e3 * e3


@njit(cache=True)
def _frames(theta, rate, table):
    """The pass over the moves: per frame e (f+1, 4), r (f+1, 3), φ (f+1,), J_ω, J_v
    (f+1, 3, n_θ), α, a (f+1, 3); row f is ground."""
    (parent, child, slide, coordinate, sign, axis, at_parent, at_child, offset, angle,
     _, _, n_frames, _) = table
    n = theta.shape[0]
    e = np.zeros((n_frames + 1, 4))
    rot = np.zeros((n_frames + 1, 3, 3))
    r = np.zeros((n_frames + 1, 3))
    phi = np.zeros(n_frames + 1)
    jw = np.zeros((n_frames + 1, 3, n))
    jv = np.zeros((n_frames + 1, 3, n))
    alpha = np.zeros((n_frames + 1, 3))
    acc = np.zeros((n_frames + 1, 3))
    e[n_frames, 0] = 1.0
    for a in range(3):
        rot[n_frames, a, a] = 1.0
    for i in range(parent.shape[0]):
        p, c, k, s = parent[i], child[i], coordinate[i], sign[i]
        a_p = rot[p]
        axis_w = _times(a_p, axis[i])
        at_p = _times(a_p, at_parent[i])
        if slide[i] == 0:
            half = 0.5 * (s * theta[k])
            size = np.sin(half)
            turn = (np.cos(half), size * axis[i, 0], size * axis[i, 1], size * axis[i, 2])
            e_c = _product(_product(e[p], turn), offset[i])
            d_p = at_p
        else:
            e_c = _product(e[p], offset[i])
            step = s * theta[k]
            d_p = (at_p[0] + step * axis_w[0], at_p[1] + step * axis_w[1],
                   at_p[2] + step * axis_w[2])
        for a in range(4):
            e[c, a] = e_c[a]
        _matrix_into(rot[c], e[c])
        d_c = _times(rot[c], at_child[i])
        for a in range(3):
            r[c, a] = r[p, a] + d_p[a] - d_c[a]
        phi[c] = phi[p] + (s * theta[k] * axis[i, 2] if slide[i] == 0 else 0.0) + angle[i]
        for a in range(3):
            for j in range(n):
                jw[c, a, j] = jw[p, a, j]
        if slide[i] == 0:
            for a in range(3):
                jw[c, a, k] += s * axis_w[a]
        for j in range(n):
            before = _cross(d_p, jw[p, :, j])
            after = _cross(d_c, jw[c, :, j])
            for a in range(3):
                jv[c, a, j] = jv[p, a, j] - before[a] + after[a]
        if slide[i] == 1:
            for a in range(3):
                jv[c, a, k] += s * axis_w[a]
        w_p, w = np.zeros(3), np.zeros(3)
        for a in range(3):
            for j in range(n):
                w_p[a] += jw[p, a, j] * rate[j]
                w[a] += jw[c, a, j] * rate[j]
        spin = (0.0, 0.0, 0.0)
        if slide[i] == 0:
            turning = s * rate[k]
            spin = _cross(w_p, (turning * axis_w[0], turning * axis_w[1], turning * axis_w[2]))
        for a in range(3):
            alpha[c, a] = alpha[p, a] + spin[a]
        al_p = alpha[p]
        one, two = _cross(al_p, d_p), _cross(w_p, _cross(w_p, d_p))
        three, four = _cross(alpha[c], d_c), _cross(w, _cross(w, d_c))
        for a in range(3):
            acc[c, a] = acc[p, a] + one[a] + two[a] - three[a] - four[a]
        if slide[i] == 1:
            coriolis = _cross(w_p, axis_w)
            for a in range(3):
                acc[c, a] = acc[c, a] + 2.0 * s * rate[k] * coriolis[a]
    return e, r, phi, jw, jv, alpha, acc


@njit(cache=True)
def tree_pass(theta, rate, table):
    """q = g(θ) (n,), B = ∂g/∂θ (n, n_θ) and Ḃθ̇ (n,) at θ, θ̇ (n_θ,) in the absolute layout
    (planar x, y, φ; spatial r and Euler parameters): m, rad or Euler parameters; B per unit
    coordinate (rad or m); Ḃθ̇ in m/s², rad/s² or 1/s².  ``table`` is :func:`tree_table`'s."""
    e, r, phi, jw, jv, alpha, acc = _frames(theta, rate, table)
    turns, signs, planar = table[10], table[11], table[13]
    bodies, n = turns.shape[0], theta.shape[0]
    nc = PLANAR_NC if planar else SPATIAL_NC
    q = np.empty(bodies * nc)
    b = np.zeros((bodies * nc, n))
    bias = np.empty(bodies * nc)
    for i in range(bodies):
        k = i * nc
        if planar:
            q[k], q[k + 1], q[k + 2] = r[i, 0], r[i, 1], phi[i] + turns[i]
            for j in range(n):
                b[k, j], b[k + 1, j], b[k + 2, j] = jv[i, 0, j], jv[i, 1, j], jw[i, 2, j]
            bias[k], bias[k + 1], bias[k + 2] = acc[i, 0], acc[i, 1], alpha[i, 2]
            continue
        sign = signs[i]
        scale = 0.5 * sign
        e0, e1, e2, e3 = e[i, 0], e[i, 1], e[i, 2], e[i, 3]
        # ½σ L(e), L(e) = [−ēᵀ; e₀I − [ē]×] (4, 3)
        rate_map = ((scale * -e1, scale * -e2, scale * -e3), (scale * e0, scale * e3, scale * -e2),
                    (scale * -e3, scale * e0, scale * e1), (scale * e2, scale * -e1, scale * e0))
        for a in range(3):
            q[k + a] = r[i, a]
            bias[k + a] = acc[i, a]
            for j in range(n):
                b[k + a, j] = jv[i, a, j]
        for a in range(4):
            q[k + 3 + a] = sign * e[i, a]
        omega = np.zeros(3)
        for a in range(3):
            for j in range(n):
                omega[a] += jw[i, a, j] * rate[j]
        square = omega[0] * omega[0] + omega[1] * omega[1] + omega[2] * omega[2]
        for a in range(4):
            row = rate_map[a]
            for j in range(n):
                b[k + 3 + a, j] = row[0] * jw[i, 0, j] + row[1] * jw[i, 1, j] + row[2] * jw[i, 2, j]
            bias[k + 3 + a] = (row[0] * alpha[i, 0] + row[1] * alpha[i, 1] + row[2] * alpha[i, 2]
                               - 0.25 * sign * square * e[i, a])
    return q, b, bias
