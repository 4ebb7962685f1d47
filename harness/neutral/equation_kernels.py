"""Compiled (numba) joint equations of the neutral model for one state: the rows, Jacobian and
velocity residuals of :mod:`mbh._harness.neutral.equations`, with the joint rows flattened into a
numeric table (:class:`RowTable`), for the right-hand sides of :mod:`mbh._harness.neutral.dynamics_kernels`.

Only the order of the floating-point operations differs from the numpy originals
(``tests/neutral/test_reference_speed.py`` compares them).  Nothing here imports the in-house
formulation (docs/design.md, Layers).

Row table: one entry per joint-equation row, in :class:`~mbh._harness.neutral.equations.JointEquations`
order: ``kind`` (m,) one of the ``_ROW_*`` codes, ``bodies`` (m, 2) body indices (−1: ground),
``vectors`` (m, 3, 3) body-frame points/axes (see :func:`row_gradients`), ``offset`` and
``rate`` (m,) the driver terms (rad or m, rad/s or m/s), ``wrapped`` (m,) whether the row is an
angle wrapped to (−π, π].  The routes' rows are ``combine @ base − shift`` with ``wrap_out``
(the branch relations of :class:`~mbh._harness.references.routes.BranchEquations`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from mbh._harness.neutral.equations import (JointEquations, _AxisTilt, _CrossAxes, _PlanarAngle,
                                     _PointGap, _Projection, _Twist)

_ROW_GAP, _ROW_PROJECTION, _ROW_TILT_NORMAL, _ROW_TILT_BINORMAL = 0, 1, 2, 3
_ROW_TWIST, _ROW_CROSS, _ROW_PLANAR_ANGLE = 4, 5, 6
#: numba with numpy's floating-point semantics (x / 0 gives inf or nan, as on the numpy path, so
#: that DOP853 rejects a trial step that leaves the mechanism's domain instead of the route
#: failing).
compiled = numba.njit(cache=True, error_model="numpy")


@dataclass(frozen=True)
class RowTable:
    """Joint-equation rows as arrays, combined into the route's rows (module docstring).

    Attributes
    ----------
    kind, bodies, vectors, offset, rate, wrapped
        The base rows, shapes (m,), (m, 2), (m, 3, 3), (m,), (m,), (m,).
    combine : ndarray, shape (m_out, m)
        The route's rows as combinations of the base rows.
    shift : ndarray, shape (m_out,)
        Subtracted after combining (the branch relations' start values, the driver's value).
    wrap_out : ndarray of bool, shape (m_out,)
        Rows wrapped to (−π, π] after combining.
    """

    kind: np.ndarray
    bodies: np.ndarray
    vectors: np.ndarray
    offset: np.ndarray
    rate: np.ndarray
    wrapped: np.ndarray
    combine: np.ndarray
    shift: np.ndarray
    wrap_out: np.ndarray

    def arrays(self) -> tuple:
        """The arrays in the order the kernels take them."""
        return (self.kind, self.bodies, self.vectors, self.offset, self.rate, self.wrapped,
                self.combine, self.shift, self.wrap_out)


def _block_rows(block) -> list[tuple[int, np.ndarray]]:
    """(kind, vectors (3, 3)) of each row of one joint-equation block."""
    def stack(*vectors):
        table = np.zeros((3, 3))
        for k, vector in enumerate(vectors):
            table[k] = vector
        return table

    if isinstance(block, _PointGap):
        return [(_ROW_GAP, stack(block.point1, block.point2, np.eye(3)[k])) for k in block.axes]
    if isinstance(block, _Projection):
        return [(_ROW_PROJECTION, stack(block.point1, block.point2, direction))
                for direction in block.directions]
    if isinstance(block, _AxisTilt):
        vectors = stack(block.axis1, block.normal1, block.axis2)
        return [(_ROW_TILT_NORMAL, vectors), (_ROW_TILT_BINORMAL, vectors)]
    if isinstance(block, _Twist):
        return [(_ROW_TWIST, stack(block.axis1, block.normal1, block.normal2))]
    if isinstance(block, _CrossAxes):
        return [(_ROW_CROSS, stack(block.axis1, block.axis2))]
    if isinstance(block, _PlanarAngle):
        return [(_ROW_PLANAR_ANGLE, stack())]
    raise TypeError(f"joint-equation block {type(block).__name__} has no compiled form")


def row_table(equations: JointEquations, combine=None, shift=None, wrap_out=None) -> RowTable:
    """The rows of ``equations`` as a :class:`RowTable` (default: the rows themselves)."""
    kinds, bodies, vectors, offset, rate, wrapped = [], [], [], [], [], []
    for block in equations._blocks:
        for kind, table in _block_rows(block):
            kinds.append(kind)
            bodies.append((block.body1, block.body2))
            vectors.append(table)
            offset.append(block.offset)
            rate.append(block.rate)
            wrapped.append(block.wrapped)
    m = len(kinds)
    return RowTable(np.array(kinds, dtype=np.int64), np.array(bodies, dtype=np.int64).reshape(m, 2),
                    np.array(vectors, dtype=float).reshape(m, 3, 3), np.array(offset, dtype=float),
                    np.array(rate, dtype=float), np.array(wrapped, dtype=np.bool_),
                    np.eye(m) if combine is None else np.asarray(combine, dtype=float),
                    np.zeros(m) if shift is None else np.asarray(shift, dtype=float),
                    np.zeros(m, dtype=np.bool_) if wrap_out is None else np.asarray(wrap_out))


# -- vector helpers ---------------------------------------------------------------------
@compiled
def cross(a, b):
    """a × b of two 3-vectors."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])


@compiled
def dot(a, b):
    """a · b of two 3-vectors."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@compiled
def wrap(angle):
    """An angle wrapped to (−π, π], rad (:func:`mbh._harness.model.outputs.wrap_angle`)."""
    return np.pi - (np.pi - angle) % (2.0 * np.pi)


@compiled
def _atan2_gradient(y, x, grad_y, grad_x):
    return (x * grad_y - y * grad_x) / (x * x + y * y)


@compiled
def rotations(quaternion):
    """Rotation matrices (n_b, 3, 3) of scalar-first quaternions (n_b, 4), normalised."""
    n = quaternion.shape[0]
    matrix = np.empty((n, 3, 3))
    for b in range(n):
        norm = np.sqrt(quaternion[b, 0] ** 2 + quaternion[b, 1] ** 2 + quaternion[b, 2] ** 2
                       + quaternion[b, 3] ** 2)
        w, x, y, z = (quaternion[b, 0] / norm, quaternion[b, 1] / norm,
                      quaternion[b, 2] / norm, quaternion[b, 3] / norm)
        matrix[b, 0, 0] = w * w + x * x - y * y - z * z
        matrix[b, 0, 1] = 2.0 * (x * y - z * w)
        matrix[b, 0, 2] = 2.0 * (x * z + y * w)
        matrix[b, 1, 0] = 2.0 * (x * y + z * w)
        matrix[b, 1, 1] = w * w - x * x + y * y - z * z
        matrix[b, 1, 2] = 2.0 * (y * z - x * w)
        matrix[b, 2, 0] = 2.0 * (x * z - y * w)
        matrix[b, 2, 1] = 2.0 * (y * z + x * w)
        matrix[b, 2, 2] = w * w - x * x - y * y + z * z
    return matrix


@compiled
def world_vector(rotation, body, local):
    """World image of a body-frame vector (ground, −1: the vector itself)."""
    if body < 0:
        return local.copy()
    return rotation[body] @ local


@compiled
def _origin(position, body):
    return np.zeros(3) if body < 0 else position[body].copy()


@compiled
def _planar_angle_gradient(rotation, body):
    """Angle φ of a body's x axis about z and its gradient with respect to ω (3,)."""
    x = np.array([1.0, 0.0, 0.0]) if body < 0 else rotation[body][:, 0].copy()
    grad = _atan2_gradient(x[1], x[0], cross(x, np.array([0.0, 1.0, 0.0])),
                           cross(x, np.array([1.0, 0.0, 0.0])))
    return np.arctan2(x[1], x[0]), grad


@compiled
def row_gradients(kind, bodies, vectors, position, rotation):
    """Raw rows (m,) and their gradients with respect to the twists [v, ω] of body 1 and
    body 2, (m, 6) each (joint_equations' blocks, row by row)."""
    m = kind.shape[0]
    raw = np.empty(m)
    g1 = np.zeros((m, 6))
    g2 = np.zeros((m, 6))
    for r in range(m):
        b1, b2 = bodies[r, 0], bodies[r, 1]
        k = kind[r]
        if k == _ROW_GAP or k == _ROW_PROJECTION:
            arm1 = world_vector(rotation, b1, vectors[r, 0])
            arm2 = world_vector(rotation, b2, vectors[r, 1])
            gap = _origin(position, b2) + arm2 - _origin(position, b1) - arm1
            if k == _ROW_GAP:
                e = vectors[r, 2].copy()
                angular1 = -cross(arm1, e)
            else:
                e = world_vector(rotation, b1, vectors[r, 2])
                angular1 = cross(e, gap + arm1)
            raw[r] = dot(e, gap)
            g1[r, :3] = -e
            g1[r, 3:] = angular1
            g2[r, :3] = e
            g2[r, 3:] = cross(arm2, e)
        elif k == _ROW_PLANAR_ANGLE:
            phi1, grad1 = _planar_angle_gradient(rotation, b1)
            phi2, grad2 = _planar_angle_gradient(rotation, b2)
            raw[r] = phi2 - phi1
            g1[r, 3:] = -grad1
            g2[r, 3:] = grad2
        else:
            first = world_vector(rotation, b1, vectors[r, 0])
            second = world_vector(rotation, b1, vectors[r, 1])
            if k == _ROW_CROSS:
                a2 = world_vector(rotation, b2, vectors[r, 1])
                perpendicular = cross(first, a2)
                size = np.sqrt(dot(perpendicular, perpendicular))
                raw[r] = np.arctan2(dot(first, a2), size)
                g = perpendicular / size
            elif k == _ROW_TWIST:
                f1 = cross(first, second)
                h2 = world_vector(rotation, b2, vectors[r, 2])
                y, x = dot(f1, h2), dot(second, h2)
                raw[r] = np.arctan2(y, x)
                g = _atan2_gradient(y, x, cross(f1, h2), cross(second, h2))
            else:
                a2 = world_vector(rotation, b2, vectors[r, 2])
                side = -cross(first, second) if k == _ROW_TILT_NORMAL else second
                y, x = dot(side, a2), dot(first, a2)
                raw[r] = np.arctan2(y, x)
                g = _atan2_gradient(y, x, cross(side, a2), cross(first, a2))
            g1[r, 3:] = g
            g2[r, 3:] = -g
    return raw, g1, g2


@compiled
def combined_rows(values, combine, shift, wrap_out):
    out = combine @ values - shift
    for r in range(out.shape[0]):
        if wrap_out[r]:
            out[r] = wrap(out[r])
    return out


@compiled
def residuals(kind, bodies, vectors, offset, rate, wrapped, combine, shift, wrap_out,
              position, quaternion, t):
    """The route's rows, shape (m_out,), m or rad, at time t (s)."""
    raw, _, _ = row_gradients(kind, bodies, vectors, position, rotations(quaternion))
    values = raw - (offset + rate * t)
    for r in range(values.shape[0]):
        if wrapped[r]:
            values[r] = wrap(values[r])
    return combined_rows(values, combine, np.asarray(shift), wrap_out)


@compiled
def jacobian_of(bodies, g1, g2, combine, planar, n_bodies):
    size = 3 if planar else 6
    columns = np.array([0, 1, 5]) if planar else np.arange(6)
    base = np.zeros((g1.shape[0], size * n_bodies))
    for r in range(g1.shape[0]):
        for side in range(2):
            body = bodies[r, side]
            if body < 0:
                continue
            g = g1 if side == 0 else g2
            for c in range(size):
                base[r, size * body + c] += g[r, columns[c]]
    return combine @ base


@compiled
def jacobian(kind, bodies, vectors, combine, planar, position, quaternion):
    """∂(route rows)/∂(body twists), shape (m_out, twist_size·n_b) ([v, ω] or [v_x, v_y, ω_z])."""
    _, g1, g2 = row_gradients(kind, bodies, vectors, position, rotations(quaternion))
    return jacobian_of(bodies, g1, g2, combine, planar, position.shape[0])


@compiled
def row_rates(bodies, rate, g1, g2, combine, velocity, angular_velocity):
    m = g1.shape[0]
    values = np.empty(m)
    for r in range(m):
        total = 0.0
        for side in range(2):
            body = bodies[r, side]
            if body < 0:
                continue
            g = g1 if side == 0 else g2
            for c in range(3):
                total += g[r, c] * velocity[body, c] + g[r, 3 + c] * angular_velocity[body, c]
        values[r] = total - rate[r]
    return combine @ values


@compiled
def velocity_residuals(kind, bodies, vectors, rate, combine, position, quaternion, velocity,
                       angular_velocity):
    """Rates of the route's rows, shape (m_out,), m/s or rad/s."""
    _, g1, g2 = row_gradients(kind, bodies, vectors, position, rotations(quaternion))
    return row_rates(bodies, rate, g1, g2, combine, velocity, angular_velocity)



class CompiledRows:
    """A :class:`RowTable` behind the interface of
    :class:`~mbh._harness.references.routes.BranchEquations` for one state (no leading sample axes).

    Parameters
    ----------
    table : RowTable
    planar : bool
        Planar twist columns [v_x, v_y, ω_z].
    driver_row : bool
        The last row is the driver's: :attr:`drive` (rad or m) is subtracted from it.
    """

    def __init__(self, table: RowTable, planar: bool, driver_row: bool = False):
        self.table, self.planar = table, planar
        self.m = table.combine.shape[0]
        self._driver = np.zeros(self.m)
        if driver_row:
            self._driver[-1] = 1.0
        self.drive = 0.0

    @property
    def shift(self) -> np.ndarray:
        """Subtracted from the combined rows: the table's shift and :attr:`drive`, shape (m,)."""
        return self.table.shift + self.drive * self._driver

    def arrays(self) -> tuple:
        """The table's arrays (:meth:`RowTable.arrays`) with :attr:`shift` for the current
        :attr:`drive`."""
        t = self.table
        return (t.kind, t.bodies, t.vectors, t.offset, t.rate, t.wrapped, t.combine, self.shift,
                t.wrap_out)

    def residuals(self, position, quaternion) -> np.ndarray:
        """Rows at t = 0, shape (m,), m or rad."""
        return residuals(*self.arrays(), np.asarray(position, dtype=float),
                         np.asarray(quaternion, dtype=float), 0.0)

    def jacobian(self, position, quaternion) -> np.ndarray:
        """∂(rows)/∂(body twists), shape (m, twist_size·n_bodies)."""
        t = self.table
        return jacobian(t.kind, t.bodies, t.vectors, t.combine, self.planar,
                        np.asarray(position, dtype=float), np.asarray(quaternion, dtype=float))

    def velocity_residuals(self, position, quaternion, velocity, angular_velocity) -> np.ndarray:
        """Rates of the rows, shape (m,), m/s or rad/s."""
        t = self.table
        return velocity_residuals(t.kind, t.bodies, t.vectors, t.rate, t.combine,
                                  *(np.asarray(a, dtype=float) for a in
                                    (position, quaternion, velocity, angular_velocity)))
