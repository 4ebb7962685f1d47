"""The engine-neutral mechanism model.

A :class:`Mechanism` is what a scenario file describes once validated: rigid bodies with their
centroidal inertia, joints between pairs of bodies (``ground`` allowed), applied forces, the initial
driver state, the duration and the named outputs.  Every adapter, the in-house formulation
included, builds its model from this object alone (docs/design.md, rule 1).

Frames and units (SI throughout)
--------------------------------
* Each body has a body frame at its centre of mass.  ``Body.position`` (m) and ``Body.rotation``
  (3×3, body → world) give that frame in the *reference configuration* drawn by the scenario.
* Joint geometry is stored in body frames (``point1``/``axis1`` on ``body1``, ``point2``/``axis2``
  on ``body2``), as in Rouvinen's table 6 (Rouvinen 2003).  The scenario file writes it in world
  coordinates at the reference configuration; the loader converts.
* Ground is the world frame; its name is :data:`GROUND`.
* Planar mechanisms move in the world x–y plane; their joint axes are +z.
"""

from __future__ import annotations

import dataclasses
import hashlib
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from scipy.spatial.distance import pdist

from mbh._harness.common.digest import feed

GROUND = "ground"

JOINT_TYPES = ("revolute", "prismatic", "spherical", "universal", "cylindrical", "translational")
PLANAR_JOINT_TYPES = ("revolute", "prismatic")
#: Number of relative degrees of freedom each joint type removes in space (Grübler, Frączek & Wojtyra 2009, eq. 1.39)
#: and in the plane (eq. 1.40).
SPATIAL_JOINT_CLASS = {
    "revolute": 5,
    "prismatic": 5,
    "translational": 5,
    "cylindrical": 4,
    "universal": 4,
    "spherical": 3,
}
PLANAR_JOINT_CLASS = {"revolute": 2, "prismatic": 2}
#: Joint types whose single coordinate can drive the mechanism (rotation or translation).
DRIVABLE = {"revolute": "angle", "prismatic": "distance", "translational": "distance",
            "cylindrical": "angle"}



def grubler_mobility(mech: "Mechanism") -> int:
    """Chebyshev–Grübler–Kutzbach mobility of ``mech``: 6 per spatial body (3 per planar body)
    less the freedoms its joints remove (Frączek & Wojtyra 2009, eq. 1.39 / 1.40).  A count on
    the model, blind to redundant equations and to the actual geometry."""
    if mech.planar:
        return 3 * len(mech.bodies) - sum(PLANAR_JOINT_CLASS[j.type] for j in mech.joints)
    return 6 * len(mech.bodies) - sum(SPATIAL_JOINT_CLASS[j.type] for j in mech.joints)

@dataclass(frozen=True)
class Body:
    """A rigid body.

    Attributes
    ----------
    name : str
    mass : float
        kg, > 0.
    inertia : ndarray, shape (3, 3)
        Centroidal inertia tensor in the body frame, kg·m².
    position : ndarray, shape (3,)
        Centre of mass in the reference configuration, world frame, m.
    rotation : ndarray, shape (3, 3)
        Orientation A (body → world) in the reference configuration (Rouvinen 2003, eq. 1).
    """

    name: str
    mass: float
    inertia: np.ndarray
    position: np.ndarray
    rotation: np.ndarray


@dataclass(frozen=True)
class Joint:
    """A joint between ``body1`` and ``body2`` (either may be :data:`GROUND`).

    Attributes
    ----------
    name, type : str
        ``type`` is one of :data:`JOINT_TYPES`.
    body1, body2 : str
    point1, point2 : ndarray, shape (3,)
        Joint point in each body's frame, m (Rouvinen 2003: ū in eq. 1).
    axis1, axis2 : ndarray, shape (3,)
        Unit joint axis in each body's frame.  For ``universal`` they are the two cross axes
        (perpendicular in the reference configuration); otherwise they are the same world line.
    normal1, normal2 : ndarray, shape (3,)
        Unit vectors perpendicular to the axis in each body's frame that coincide in the reference
        configuration: the zero of the joint's rotation coordinate, and the direction the
        translational joint keeps locked.
    """

    name: str
    type: str
    body1: str
    body2: str
    point1: np.ndarray
    point2: np.ndarray
    axis1: np.ndarray
    axis2: np.ndarray
    normal1: np.ndarray
    normal2: np.ndarray


@dataclass(frozen=True)
class BodyForce:
    """Constant force (N, world frame) applied at ``point`` (m, body frame) of ``body``."""

    body: str
    force: np.ndarray
    point: np.ndarray


@dataclass(frozen=True)
class BodyTorque:
    """Constant torque (N·m, world frame) applied to ``body``."""

    body: str
    torque: np.ndarray


@dataclass(frozen=True)
class JointActuation:
    """Constant torque (N·m, revolute/cylindrical) or force (N, prismatic/translational) along the
    joint axis, acting on ``body2`` with the reaction on ``body1``."""

    joint: str
    value: float


@dataclass(frozen=True)
class SpringDamper:
    """Point-to-point spring-damper (Rouvinen 2003, §3.1.4 generalised forces).

    ``stiffness`` N/m, ``damping`` N·s/m, ``free_length`` m; points in body frames.
    """

    name: str
    body1: str
    body2: str
    point1: np.ndarray
    point2: np.ndarray
    stiffness: float
    damping: float
    free_length: float


Force = BodyForce | BodyTorque | JointActuation | SpringDamper


@dataclass(frozen=True)
class PrescribedJointRate:
    """A joint coordinate rate prescribed at t = 0 besides the driver's (rad/s or m/s)."""

    joint: str
    rate: float


@dataclass(frozen=True)
class PrescribedPointVelocity:
    """World velocity (m/s) of a body point prescribed at t = 0.

    ``point`` is in the body frame (m); only the world ``components`` (0, 1, 2 = x, y, z) of
    ``velocity`` are prescribed, the others are left to the constraints.
    """

    body: str
    point: np.ndarray
    velocity: np.ndarray
    components: tuple[int, ...] = (0, 1, 2)


Prescribed = PrescribedJointRate | PrescribedPointVelocity


@dataclass(frozen=True)
class InitialState:
    """The initial driver state.

    ``value`` is the driver joint's coordinate (rad or m) measured from the reference
    configuration; ``rate`` its time derivative.  ``guess`` maps body names to approximate centre
    positions (m, world) that replace the reference positions as the Newton start and so pick the
    assembly branch (Frączek & Wojtyra 2009, §1.1.2, lesson on several solutions).  ``prescribed`` holds further
    velocity conditions at t = 0; together with ``rate`` they must be consistent with the
    constraints (the assembly checks it and refuses an inconsistent start).
    """

    driver: str
    value: float
    rate: float
    guess: dict[str, np.ndarray] = field(default_factory=dict)
    prescribed: tuple[Prescribed, ...] = ()


OutputKind = Literal["joint_angle", "joint_rate", "joint_position", "position", "velocity",
                     "point_position", "point_velocity"]


@dataclass(frozen=True)
class Output:
    """A named scalar quantity computed from body states.

    ``joint_angle``: rotation of ``body2`` relative to ``body1`` about the joint axis since t = 0,
    right-hand rule, unwrapped, plus ``offset`` (rad).  ``joint_rate``: its derivative (rad/s).
    ``joint_position``: slide along the joint axis since t = 0 (m).  ``position``/``velocity``:
    component ``component`` (0, 1, 2 = x, y, z) of a body's centre of mass (m, m/s).
    ``point_position``/``point_velocity``: the same for the body point ``point`` (body frame, m).
    """

    name: str
    kind: str
    target: str
    component: int = 0
    point: np.ndarray | None = None
    offset: float = 0.0


@dataclass(frozen=True)
class Mechanism:
    """A validated scenario.  See the module docstring for frames and units."""

    name: str
    kind: Literal["planar", "spatial"]
    bodies: tuple[Body, ...]
    joints: tuple[Joint, ...]
    forces: tuple[Force, ...]
    gravity: np.ndarray
    initial: InitialState
    duration: float
    outputs: tuple[Output, ...]
    #: Spacing of the evaluation grid, s (:mod:`mbh._harness.model.timegrid`): fine enough that no joint
    #: turns by π between two samples.
    sample_step: float = 0.01
    tags: tuple[str, ...] = ()
    notes: str = ""
    source: str = ""
    #: Identity of the mechanism for every cache keyed by it (the assembled start, references,
    #: generated functions' traces): a scenario file's is the digest of its text, a mechanism
    #: built in Python gets :func:`data_digest`'s; one changed with ``dataclasses.replace`` gets a
    #: hash of its own (:meth:`__post_init__`), never its original's.
    content_hash: str = ""
    #: Pairs of joints that turn by equal angles on the assembly branch the motion stays on
    #: (``[reference] equal_joint_angles``); only the reference routes use them.
    branch: tuple[tuple[str, str], ...] = ()
    #: Whether the reference takes the neutral DOP853 routes of :mod:`mbh._harness.references.routes`
    #: (``[reference] routes = "neutral"``, implied by a declared branch).
    neutral_routes: bool = False
    #: :func:`data_digest` of the mechanism ``content_hash`` was given for (set on construction).
    source_digest: str = field(default="", repr=False, compare=False)

    def __post_init__(self):
        """Give the mechanism the ``content_hash`` of what it is: :func:`data_digest` when none
        was given, and a hash of its own when ``dataclasses.replace`` changed anything the hash
        covers — a replaced start or mass under the original's hash would take the original's
        cached start and reference, and be judged against another mechanism's motion."""
        digest = data_digest(self)
        if not self.content_hash:
            object.__setattr__(self, "content_hash", digest)
        elif self.source_digest and self.source_digest != digest:
            own = hashlib.sha256(f"{self.content_hash}/{digest}".encode()).hexdigest()
            object.__setattr__(self, "content_hash", own)
        object.__setattr__(self, "source_digest", digest)

    @property
    def planar(self) -> bool:
        return self.kind == "planar"

    def body_index(self, name: str) -> int:
        """Index of body ``name`` in :attr:`bodies`, ``-1`` for ground."""
        if name == GROUND:
            return -1
        for index, body in enumerate(self.bodies):
            if body.name == name:
                return index
        raise KeyError(name)

    def joint(self, name: str) -> Joint:
        for joint in self.joints:
            if joint.name == name:
                return joint
        raise KeyError(name)

    def output(self, name: str) -> Output:
        for output in self.outputs:
            if output.name == name:
                return output
        raise KeyError(name)

    @property
    def masses(self) -> np.ndarray:
        """Body masses, shape (n_bodies,), kg."""
        return np.array([body.mass for body in self.bodies])


#: The fields of a :class:`Mechanism` that do not change what is computed for it.
_DESCRIPTIVE = ("name", "tags", "notes", "source", "content_hash", "source_digest")


def data_digest(mech: Mechanism) -> str:
    """SHA-256 (hex) of everything in ``mech`` that a computation reads (bodies, joints, forces,
    gravity, start, duration, outputs, grids, reference routes), not its name, notes or source."""
    digest = hashlib.sha256()
    for item in dataclasses.fields(mech):
        if item.name not in _DESCRIPTIVE:
            digest.update(item.name.encode())
            feed(digest, getattr(mech, item.name))
    return digest.hexdigest()


def characteristic_length(mech: Mechanism) -> float:
    """The mechanism's size, m: the largest distance between any two of its joint points and
    centres of mass in the reference configuration (ground points included).

    A single body hinged at its centre has no such distance; its largest radius of gyration
    √(tr J / m) stands in.
    """
    points = [body.position for body in mech.bodies]
    for joint in mech.joints:
        for body, point in ((joint.body1, joint.point1), (joint.body2, joint.point2)):
            if body == GROUND:
                points.append(np.asarray(point, dtype=float))
            else:
                frame = mech.bodies[mech.body_index(body)]
                points.append(frame.position + frame.rotation @ point)
    spread = float(pdist(np.array(points)).max()) if len(points) > 1 else 0.0
    gyration = max(float(np.sqrt(np.trace(b.inertia) / b.mass)) for b in mech.bodies)
    return spread if spread > 0 else gyration
