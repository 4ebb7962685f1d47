"""The constraint library: joints composed of primitive constraints (Rouvinen 2003, ch. 2, eq. 34–38;
Frączek & Wojtyra 2009, eq. 1.35), and the coordinate layout of a mechanism in absolute coordinates.

Joint compositions (spatial; ``h``, ``f`` are the two unit vectors perpendicular to the axis ``a``
on a body, ``h`` = the joint normal, ``f = a × h``):

* spherical      C^s                                            3 equations (eq. 34)
* universal      C^s + C^d1(a_i, a_j)                          4 (eq. 35)
* revolute       C^s + C^d1(a_i, h_j) + C^d1(a_i, f_j)         5 (eq. 36; the two d1 are C^p1)
* cylindrical    C^p1 + C^d2(h_i, d_ij) + C^d2(f_i, d_ij)      4 (eq. 37; the two d2 are C^p2)
* translational  cylindrical + C^d1(h_i, f_j)                  5 (eq. 38)
* prismatic      as translational

Planar: revolute = point coincidence (2 equations); prismatic = fixed relative angle + the point
of body j on the line of body i (2 equations).  Spatial bodies add θᵀθ − 1 = 0 each.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mbh._adapters.inhouse.bodies import kernels
from mbh._adapters.inhouse.numerics.banded import Sparsity, sparsity
from mbh._adapters.inhouse.bodies.bodykin import PLANAR_NC, SPATIAL_NC
from mbh._harness.model.mechanism import GROUND, Joint, Mechanism

_Z = np.array([0.0, 0.0, 1.0])


def planar_angle(rotation: np.ndarray) -> float:
    """Rotation angle about z of a planar rotation matrix (rad)."""
    return float(np.arctan2(rotation[1, 0], rotation[0, 0]))


@dataclass(frozen=True)
class Layout:
    """Absolute-coordinate layout: ``nc`` coordinates per body (3 planar, 7 spatial)."""

    n_bodies: int
    nc: int

    @property
    def n(self) -> int:
        return self.n_bodies * self.nc

    @property
    def planar(self) -> bool:
        return self.nc == PLANAR_NC


def layout_of(mech: Mechanism) -> Layout:
    return Layout(len(mech.bodies), PLANAR_NC if mech.planar else SPATIAL_NC)


class _TableBuilder:
    """Accumulates primitive constraints with a human-readable label per equation row."""

    def __init__(self, mech: Mechanism, dim: int):
        self.mech = mech
        self.dim = dim
        self.rows: list[dict] = []
        self.labels: list[str] = []
        self.m = 0

    def add(self, kind, body_i, body_j, label, ui=None, uj=None, pi=None, gj=None, const=0.0,
            driver=0):
        n_rows = self.dim if kind == kernels.POINT else 1
        zero = np.zeros(3)
        self.rows.append(dict(
            kind=kind, bi=self.mech.body_index(body_i), bj=self.mech.body_index(body_j),
            row=self.m, driver=driver, const=const,
            ui=zero if ui is None else ui, uj=zero if uj is None else uj,
            pi=zero if pi is None else pi, gj=zero if gj is None else gj))
        axes = "xyz"[:n_rows] if n_rows > 1 else [""]
        self.labels.extend(f"{label} {a}".strip() for a in axes)
        self.m += n_rows

    def arrays(self) -> dict:
        def stack(key, dtype):
            if not self.rows:
                shape = (0, 3) if key in ("ui", "uj", "pi", "gj") else (0,)
                return np.zeros(shape, dtype=dtype)
            return np.ascontiguousarray([r[key] for r in self.rows], dtype=dtype)
        ints = {key: stack(key, np.int64) for key in ("kind", "bi", "bj", "row", "driver")}
        floats = {key: stack(key, np.float64) for key in ("ui", "uj", "pi", "gj", "const")}
        return ints | floats


def _add_joint(tb: _TableBuilder, joint: Joint) -> None:
    i, j, name = joint.body1, joint.body2, f"joint {joint.name} ({joint.type})"
    if tb.mech.planar:
        if joint.type == "revolute":
            tb.add(kernels.POINT, i, j, f"{name}: point", ui=joint.point1, uj=joint.point2)
        else:  # prismatic
            tb.add(kernels.ANGLE, i, j, f"{name}: angle", const=_reference_angle(tb.mech, joint))
            tb.add(kernels.DOT_VD, i, j, f"{name}: line", ui=np.cross(_Z, joint.axis1),
                   pi=joint.point1, uj=joint.point2)
        return
    a_i, h_i = joint.axis1, joint.normal1
    f_i = np.cross(a_i, h_i)
    h_j = joint.normal2
    f_j = np.cross(joint.axis2, h_j)
    if joint.type in ("spherical", "universal", "revolute"):
        tb.add(kernels.POINT, i, j, f"{name}: point", ui=joint.point1, uj=joint.point2)
    if joint.type == "universal":
        tb.add(kernels.DOT_VV, i, j, f"{name}: cross axes", ui=a_i, uj=joint.axis2)
    if joint.type in ("revolute", "cylindrical", "translational", "prismatic"):
        tb.add(kernels.DOT_VV, i, j, f"{name}: parallel axis 1", ui=a_i, uj=h_j)
        tb.add(kernels.DOT_VV, i, j, f"{name}: parallel axis 2", ui=a_i, uj=f_j)
    if joint.type in ("cylindrical", "translational", "prismatic"):
        tb.add(kernels.DOT_VD, i, j, f"{name}: on axis 1", ui=h_i, pi=joint.point1, uj=joint.point2)
        tb.add(kernels.DOT_VD, i, j, f"{name}: on axis 2", ui=f_i, pi=joint.point1, uj=joint.point2)
    if joint.type in ("translational", "prismatic"):
        tb.add(kernels.DOT_VV, i, j, f"{name}: no rotation", ui=h_i, uj=f_j)


def _reference_angle(mech: Mechanism, joint: Joint) -> float:
    """φ_j − φ_i in the reference configuration (planar)."""
    def angle(body):
        return 0.0 if body == GROUND else planar_angle(mech.bodies[mech.body_index(body)].rotation)
    return angle(joint.body2) - angle(joint.body1)


def _reference_slide(mech: Mechanism, joint: Joint) -> float:
    """Distance along the axis between the joint points in the reference configuration (m)."""
    def world(body, u, is_point):
        if body == GROUND:
            return u
        b = mech.bodies[mech.body_index(body)]
        return b.rotation @ u + (b.position if is_point else 0.0)
    axis = world(joint.body1, joint.axis1, False)
    return float(axis @ (world(joint.body2, joint.point2, True) - world(joint.body1, joint.point1, True)))


def _add_driver(tb: _TableBuilder, joint: Joint) -> None:
    i, j, label = joint.body1, joint.body2, f"driver {joint.name}"
    if joint.type in ("prismatic", "translational"):
        tb.add(kernels.DOT_VD, i, j, label, ui=joint.axis1, pi=joint.point1, uj=joint.point2,
               const=_reference_slide(tb.mech, joint), driver=1)
    elif tb.mech.planar:
        tb.add(kernels.ANGLE, i, j, label, const=_reference_angle(tb.mech, joint), driver=1)
    else:
        tb.add(kernels.DRIVE_ROT, i, j, label, ui=joint.normal1, uj=joint.normal2,
               gj=np.cross(joint.axis2, joint.normal2), driver=1)


class ConstraintSystem:
    """Φ, Φ_q, Φ_t and γ of a mechanism's joints (and optionally its driver) as compiled kernels.

    Parameters
    ----------
    mech : Mechanism
    with_driver : bool
        Append the driving constraint θ − θ_d(t) = 0 (kinematic analysis).  Dynamics runs without.
    drive : (value, rate)
        θ_d(t) = value + rate·t, rad or m.

    Attributes
    ----------
    m : int
        Number of equations.  ``labels`` names each one (``"joint B (revolute): point x"``).
    n_joint_equations : int
        The first ``n_joint_equations`` rows are the joints'; Euler-parameter normalisation rows
        (spatial) and the driver row follow.
    """

    def __init__(self, mech: Mechanism, with_driver: bool = False, drive=(0.0, 0.0)):
        self.mech = mech
        self.layout = layout_of(mech)
        tb = _TableBuilder(mech, 2 if mech.planar else 3)
        for joint in mech.joints:
            _add_joint(tb, joint)
        self.n_joint_equations = tb.m
        if not mech.planar:
            for body in mech.bodies:
                tb.add(kernels.NORM, body.name, GROUND, f"body {body.name}: θᵀθ = 1")
        if with_driver:
            _add_driver(tb, mech.joint(mech.initial.driver))
        self.m = tb.m
        self.labels = tuple(tb.labels)
        arrays = tb.arrays()
        self._args = (self.layout.nc, *arrays.values(), np.asarray(drive, dtype=float), self.m)
        self._row_bodies = _row_bodies(arrays, self.m, 2 if mech.planar else 3)
        self._sparsity = None

    @property
    def sparsity(self) -> Sparsity:
        """Where Φ_q can be non-zero and a banded row order (:mod:`mbh._adapters.inhouse.numerics.banded`)."""
        if self._sparsity is None:
            self._sparsity = sparsity(self._row_bodies, self.layout.n_bodies, self.layout.nc)
        return self._sparsity

    @property
    def kernel_args(self) -> tuple:
        """Arguments after (q, [v,] t) for the functions of :mod:`kernels`."""
        return self._args

    def phi(self, q: np.ndarray, t: float = 0.0) -> np.ndarray:
        """Residuals, shape (m,)."""
        return kernels.phi(q, t, self._args)

    def jacobian(self, q: np.ndarray, t: float = 0.0) -> np.ndarray:
        """Φ_q, shape (m, n)."""
        return kernels.jacobian(q, t, self._args)

    def phi_t(self, q: np.ndarray, t: float = 0.0) -> np.ndarray:
        """Φ_t, shape (m,)."""
        return kernels.phi_t(q, t, self._args)

    def gamma(self, q: np.ndarray, v: np.ndarray, t: float = 0.0) -> np.ndarray:
        """γ, shape (m,)."""
        return kernels.gamma(q, v, t, self._args)


def _row_bodies(arrays: dict, m: int, dim: int) -> np.ndarray:
    """Bodies (i, j) of each equation row, −1 for ground or none, shape (m, 2)."""
    bodies = np.full((m, 2), -1, dtype=np.int64)
    for kind, i, j, row in zip(arrays["kind"], arrays["bi"], arrays["bj"], arrays["row"]):
        n_rows = dim if kind == kernels.POINT else 1
        bodies[row:row + n_rows] = (i, -1 if kind == kernels.NORM else j)
    return bodies


def reference_coordinates(mech: Mechanism) -> np.ndarray:
    """Absolute coordinates of the reference configuration, with ``initial.guess`` positions
    replacing the reference positions of the bodies it names, shape (n,)."""
    from scipy.spatial.transform import Rotation

    layout = layout_of(mech)
    q = np.zeros(layout.n)
    for index, body in enumerate(mech.bodies):
        k = index * layout.nc
        position = mech.initial.guess.get(body.name, body.position) if mech.initial else body.position
        if layout.planar:
            q[k:k + 3] = position[0], position[1], planar_angle(body.rotation)
        else:
            q[k:k + 3] = position
            q[k + 3:k + 7] = Rotation.from_matrix(body.rotation).as_quat(scalar_first=True)
    return q
