"""Hypothesis strategies that generate valid mechanisms, for property-based tests of every adapter.

Mechanisms are assembled *by construction*: the strategy first draws every body's pose (the
reference configuration), then places each joint at a world point and axis and writes that
geometry into the two bodies' frames, so the drawn configuration satisfies every joint exactly.
Two families cover the shapes the adapters must translate:

* :func:`trees` — open chains and trees of up to :data:`MAX_TREE_BODIES` bodies with every joint
  type of the mechanism's kind (:data:`~mbh._harness.model.mechanism.JOINT_TYPES`, planar
  :data:`~mbh._harness.model.mechanism.PLANAR_JOINT_TYPES`);
* :func:`ladders` — the N-four-bar family (IFToMM benchmark library): N + 1 cranks on ground
  pivots, N couplers between consecutive crank tips, N closed loops of four bars.  Planar ladders
  use revolute joints; spatial ones revolute cranks, a spherical joint at one end of each coupler
  and a universal joint at the other whose locked rotation is the coupler's line (R–S–U–R loops,
  mobility 1, the coupler's spin about its line held away from singularity).

Masses, inertias (optionally slender: one principal moment zero), gravity, the applied loads of
:mod:`mbh._harness.model.mechanism` and the driver rate are drawn too, and :func:`mechanisms` shuffles the
declaration order of bodies and joints (:func:`redeclare`), which must never change an answer.

Needs Hypothesis (the ``test`` extra of ``pyproject.toml``); nothing else in the harness imports
this module.
"""

from __future__ import annotations


import numpy as np
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from mbh._harness.model.mechanism import (
    DRIVABLE,
    GROUND,
    JOINT_TYPES,
    PLANAR_JOINT_TYPES,
    Body,
    BodyForce,
    BodyTorque,
    InitialState,
    Joint,
    JointActuation,
    Mechanism,
    SpringDamper,
    data_digest,
)

#: Largest number of bodies of a generated tree.
MAX_TREE_BODIES = 6
#: Largest number of loops of a generated ladder (2 loops = 5 bodies, the N-four-bar with N = 2).
MAX_LADDER_LOOPS = 2
_Z = np.array([0.0, 0.0, 1.0])

_coordinate = st.floats(-1.0, 1.0, allow_nan=False, allow_infinity=False)
_positive = st.floats(0.5, 3.0, allow_nan=False, allow_infinity=False)


@st.composite
def _unit_vectors(draw, planar: bool = False) -> np.ndarray:
    """A unit vector (in the x–y plane if ``planar``), shape (3,)."""
    angle = draw(st.floats(-np.pi, np.pi))
    if planar:
        return np.array([np.cos(angle), np.sin(angle), 0.0])
    height = draw(st.floats(-1.0, 1.0))
    radius = np.sqrt(1.0 - height * height)
    return np.array([radius * np.cos(angle), radius * np.sin(angle), height])


@st.composite
def _points(draw, planar: bool, centre=np.zeros(3),  # noqa: B008 (read only)
            spread: float = 1.0) -> np.ndarray:
    """A world point within ``spread`` m of ``centre`` per coordinate (z = 0 if ``planar``)."""
    offset = np.array([draw(_coordinate), draw(_coordinate), 0.0 if planar else draw(_coordinate)])
    return np.asarray(centre, dtype=float) + spread * offset


@st.composite
def _rotations(draw, planar: bool) -> np.ndarray:
    """A rotation matrix (about z if ``planar``), shape (3, 3)."""
    if planar:
        return Rotation.from_rotvec(draw(st.floats(-np.pi, np.pi)) * _Z).as_matrix()
    axis = draw(_unit_vectors())
    return Rotation.from_rotvec(draw(st.floats(0.0, np.pi)) * axis).as_matrix()


@st.composite
def _perpendicular(draw, axis: np.ndarray, planar: bool) -> np.ndarray:
    """A unit vector perpendicular to unit ``axis``: in the plane for the planar z axis, z for a
    planar in-plane axis (as the scenario loader chooses)."""
    if planar:
        return _Z.copy() if abs(axis[2]) < 0.5 else draw(_unit_vectors(planar=True))
    trial = draw(_unit_vectors())
    trial = trial - axis * (trial @ axis)
    if np.linalg.norm(trial) < 1e-3:
        trial = np.cross(axis, np.eye(3)[int(np.argmin(np.abs(axis)))])
    # Project again: after the first pass's cancellation trial·axis is ~1e-16 / |trial|, which
    # the normalisation scales up (to ~1e-14; a normal that far off tilts the neutral revolute
    # joint's axis by as much, which Pinocchio's tree joint cannot follow).  Twice: round-off
    # (figures: docs/measurements.md, section "Generated mechanisms").
    trial = trial - axis * (trial @ axis)
    return trial / np.linalg.norm(trial)


@st.composite
def _inertias(draw, mass: float, slender: bool, planar: bool) -> np.ndarray:
    """Centroidal inertia (kg·m², shape (3, 3)) of a body of ``mass`` with random principal axes
    (one of them z if ``planar``).

    Principal moments satisfy the triangle inequality; a slender body has one moment zero (a bar
    about its own axis, in the plane if ``planar``) and the other two equal.
    """
    size = draw(st.floats(0.2, 1.5))
    if slender:
        moments = np.array([0.0, 1.0, 1.0]) * mass * size ** 2 / 12.0
    else:
        a, b = draw(st.floats(0.2, 1.0)), draw(st.floats(0.2, 1.0))
        moments = mass * size ** 2 / 12.0 * np.array([a + b, a + 1.0, b + 1.0])
    axes = draw(_rotations(planar))
    return axes @ np.diag(moments) @ axes.T


@st.composite
def _bodies(draw, name: str, planar: bool, centre: np.ndarray, allow_slender: bool) -> Body:
    mass = draw(_positive)
    slender = allow_slender and draw(st.booleans())
    return Body(name=name, mass=mass, inertia=draw(_inertias(mass, slender, planar)),
                position=np.asarray(centre, dtype=float), rotation=draw(_rotations(planar)))


def _local(bodies: dict[str, Body], name: str, point: np.ndarray | None,
           direction: np.ndarray | None) -> tuple:
    """World point and direction written in body ``name``'s frame (ground: unchanged)."""
    if name == GROUND:
        return point, direction
    body = bodies[name]
    return (None if point is None else body.rotation.T @ (point - body.position),
            None if direction is None else body.rotation.T @ direction)


@st.composite
def _joint_axes(draw, kind: str, planar: bool, locked: np.ndarray | None) -> np.ndarray:
    """A joint axis: z for a planar revolute, in the plane for a planar prismatic, square to
    ``locked`` for a universal joint that locks it, otherwise any direction."""
    if planar:
        return _Z if kind == "revolute" else draw(_unit_vectors(planar=True))
    if kind == "universal" and locked is not None:
        return draw(_perpendicular(locked, planar))
    return draw(_unit_vectors())


@st.composite
def _joints(draw, name: str, kind: str, body1: str, body2: str, bodies: dict[str, Body],
            point: np.ndarray, planar: bool, axis: np.ndarray | None = None,
            locked: np.ndarray | None = None) -> Joint:
    """Joint ``name`` of type ``kind`` at world ``point``, assembled in the drawn configuration.

    The two bodies are swapped with probability one half, so trees run both ways along joints.
    ``axis`` (unit, world) is the joint axis and ``locked`` (unit, world) the relative rotation
    a universal joint locks (its cross axes are drawn perpendicular to it); None draws them.
    """
    if draw(st.booleans()):
        body1, body2 = body2, body1
    if axis is None:
        axis = draw(_joint_axes(kind, planar, locked))
    if kind == "universal":
        second = draw(_perpendicular(axis, planar)) if locked is None else np.cross(locked, axis)
        normal = np.cross(axis, second)
    else:
        second = axis
        normal = draw(_perpendicular(axis, planar))
    point1, axis1 = _local(bodies, body1, point, axis)
    point2, axis2 = _local(bodies, body2, point, second)
    _, normal1 = _local(bodies, body1, None, normal)
    _, normal2 = _local(bodies, body2, None, normal)
    return Joint(name=name, type=kind, body1=body1, body2=body2, point1=point1, point2=point2,
                 axis1=axis1, axis2=axis2, normal1=normal1, normal2=normal2)


@st.composite
def trees(draw, planar: bool, allow_slender: bool = True) -> tuple:
    """Bodies and joints of an open chain or tree (2 to :data:`MAX_TREE_BODIES` bodies).

    Returns
    -------
    tuple
        ``(bodies, joints, driver)``: tuples of :class:`Body` and :class:`Joint`, and the name of
        a drivable joint on ground.
    """
    types = PLANAR_JOINT_TYPES if planar else JOINT_TYPES
    count = draw(st.integers(2, MAX_TREE_BODIES))
    bodies: dict[str, Body] = {}
    joints = []
    for index in range(count):
        name = f"b{index}"
        parent = GROUND if index == 0 else draw(st.sampled_from([GROUND, *bodies]))
        base = np.zeros(3) if parent == GROUND else bodies[parent].position
        bodies[name] = draw(_bodies(name, planar, draw(_points(planar, base)), allow_slender))
        kind = draw(st.sampled_from([t for t in types if index > 0 or t in DRIVABLE]))
        point = draw(_points(planar, 0.5 * (base + bodies[name].position), 0.5))
        joints.append(draw(_joints(f"j{index}", kind, parent, name, bodies, point, planar)))
    return tuple(bodies.values()), tuple(joints), "j0"


@st.composite
def _tilted_z(draw) -> np.ndarray:
    """A unit vector within 45° of z: crank axes that move the tips along the couplers, away
    from the dead-centre positions where a crank tip moves square to its coupler."""
    tilt = draw(_points(False, spread=0.5)) * np.array([1.0, 1.0, 0.0])
    return (_Z + tilt) / np.linalg.norm(_Z + tilt)


@st.composite
def ladders(draw, planar: bool, allow_slender: bool = True) -> tuple:
    """Bodies and joints of an N-four-bar ladder, N = 1 .. :data:`MAX_LADDER_LOOPS`.

    Cranks ``crank0..crankN`` turn on ground pivots; coupler ``coupler{i}`` joins the tips of
    cranks i and i + 1.  Returns ``(bodies, joints, driver)`` as :func:`trees`.
    """
    loops = draw(st.integers(1, MAX_LADDER_LOOPS))
    pivots = [draw(_points(planar, np.array([1.5 * i, 0.0, 0.0]), 0.4)) for i in range(loops + 1)]
    tips = [draw(_points(planar, pivot + np.array([0.0, 1.0, 0.0]), 0.4)) for pivot in pivots]
    bodies: dict[str, Body] = {}
    for i, (pivot, tip) in enumerate(zip(pivots, tips)):
        centre = draw(_points(planar, 0.5 * (pivot + tip), 0.1))
        bodies[f"crank{i}"] = draw(_bodies(f"crank{i}", planar, centre, allow_slender))
    for i in range(loops):
        centre = draw(_points(planar, 0.5 * (tips[i] + tips[i + 1]), 0.1))
        bodies[f"coupler{i}"] = draw(_bodies(f"coupler{i}", planar, centre, allow_slender))
    start, end = ("revolute", "revolute") if planar else ("spherical", "universal")
    joints = [draw(_joints(f"pivot{i}", "revolute", GROUND, f"crank{i}", bodies, pivot, planar,
                           axis=_Z if planar else draw(_tilted_z())))
              for i, pivot in enumerate(pivots)]
    for i in range(loops):
        joints.append(draw(_joints(f"tip{i}a", start, f"crank{i}", f"coupler{i}", bodies,
                                   tips[i], planar)))
        along = (tips[i + 1] - tips[i]) / np.linalg.norm(tips[i + 1] - tips[i])
        joints.append(draw(_joints(f"tip{i}b", end, f"coupler{i}", f"crank{i + 1}", bodies,
                                   tips[i + 1], planar, locked=along)))
    return tuple(bodies.values()), tuple(joints), "pivot0"


@st.composite
def _forces(draw, bodies: tuple[Body, ...], joints: tuple[Joint, ...], planar: bool) -> tuple:
    """Zero or more of: a joint actuation, a body force, a body torque, a spring-damper."""
    names = [body.name for body in bodies]
    forces = []
    drivable = [joint for joint in joints if joint.type in DRIVABLE]
    if drivable and draw(st.booleans()):
        forces.append(JointActuation(draw(st.sampled_from(drivable)).name,
                                     draw(st.floats(-5.0, 5.0))))
    if draw(st.booleans()):
        vector = draw(_points(planar, spread=5.0))
        forces.append(BodyForce(draw(st.sampled_from(names)), vector,
                                draw(_points(planar, spread=0.3))))
    if draw(st.booleans()):
        torque = draw(_points(False, spread=2.0))
        forces.append(BodyTorque(draw(st.sampled_from(names)), torque * _Z if planar else torque))
    if draw(st.booleans()):
        forces.append(draw(_springs(bodies, planar)))
    return tuple(forces)


@st.composite
def _springs(draw, bodies: tuple[Body, ...], planar: bool) -> SpringDamper:
    """A spring-damper between two bodies (or a body and ground) whose points lie 0.2 to 1 m
    apart in the drawn configuration (a zero length has no direction)."""
    ends = draw(st.lists(st.sampled_from([GROUND, *(body.name for body in bodies)]),
                         min_size=2, max_size=2, unique=True))
    by_name = {body.name: body for body in bodies}
    first = by_name[ends[0]].position if ends[0] in by_name else np.zeros(3)
    start = draw(_points(planar, first, 0.3))
    end = start + draw(st.floats(0.2, 1.0)) * draw(_unit_vectors(planar=planar))
    point1, _ = _local(by_name, ends[0], start, None)
    point2, _ = _local(by_name, ends[1], end, None)
    return SpringDamper("spring", ends[0], ends[1], point1, point2, draw(st.floats(0.0, 50.0)),
                        draw(st.floats(0.0, 2.0)), draw(st.floats(0.1, 1.0)))


_AXES = tuple(np.eye(3))
#: Principal moments of :func:`aligned_mechanisms`' bodies over m/12 (kg·m² per kg): bars along
#: x and z, a disc, and a slender bar along y (no moment about y; the joints on the x axis hold
#: its spin).
_ALIGNED_MOMENTS = ((0.02, 1.0, 1.0), (1.0, 1.0, 0.02), (0.5, 0.5, 1.0), (1.0, 0.0, 1.0))


@st.composite
def aligned_mechanisms(draw, planar: bool | None = None) -> Mechanism:
    """A chain of 2 to 4 bodies with a start of exact zeros and symmetry: bodies at (i + ½, 0, 0)
    m in the identity orientation (Euler parameters (1, 0, 0, 0)), principal axes along the
    world's (:data:`_ALIGNED_MOMENTS`, slender bars included), joints at (i, 0, 0) with coordinate axes, spring-dampers (stiffness up to 1e5 N/m)
    along coordinate directions, gravity along −y or −z, a driver rate of 0 or ±1 — the starts
    the random poses of :func:`mechanisms` never draw.

    Parameters
    ----------
    planar : bool or None
        Force the kind; None draws it.
    """
    planar = draw(st.booleans()) if planar is None else planar
    types = PLANAR_JOINT_TYPES if planar else JOINT_TYPES
    count = draw(st.integers(2, 4))
    bodies: dict[str, Body] = {}
    joints = []
    for index in range(count):
        name, mass = f"b{index}", draw(st.sampled_from([1.0, 2.0]))
        moments = mass / 12.0 * np.array(draw(st.sampled_from(_ALIGNED_MOMENTS)))
        bodies[name] = Body(name=name, mass=mass, inertia=np.diag(moments),
                            position=np.array([index + 0.5, 0.0, 0.0]), rotation=np.eye(3))
        kind = draw(st.sampled_from([t for t in types if index > 0 or t in DRIVABLE]))
        axis = _Z if planar and kind == "revolute" else draw(st.sampled_from(
            _AXES[:2] if planar else _AXES))
        joints.append(draw(_joints(f"j{index}", kind, GROUND if index == 0 else f"b{index - 1}",
                                   name, bodies, np.array([float(index), 0.0, 0.0]), planar,
                                   axis=axis)))
    forces = []
    for k in range(draw(st.integers(0, 2))):
        ends = draw(st.lists(st.sampled_from([GROUND, *bodies]), min_size=2, max_size=2,
                             unique=True))
        start = bodies[ends[0]].position if ends[0] in bodies else np.zeros(3)
        end = start + draw(st.sampled_from(_AXES[:2] if planar else _AXES))
        point1, _ = _local(bodies, ends[0], start, None)
        point2, _ = _local(bodies, ends[1], end, None)
        forces.append(SpringDamper(f"spring{k}", ends[0], ends[1], point1, point2,
                                   draw(st.sampled_from([1e2, 1e4, 1e5])),
                                   draw(st.sampled_from([0.0, 10.0])),
                                   draw(st.sampled_from([1.0, 0.9]))))
    gravity = np.array([0.0, -9.81, 0.0]) if planar or draw(st.booleans()) else \
        np.array([0.0, 0.0, -9.81])
    mech = Mechanism(
        name="generated", kind="planar" if planar else "spatial", bodies=tuple(bodies.values()),
        joints=tuple(joints), forces=tuple(forces), gravity=gravity,
        initial=InitialState(driver="j0", value=0.0,
                             rate=draw(st.sampled_from([0.0, 1.0, -1.0]))),
        duration=1.0, outputs=(), tags=("generated",), source="mbh._harness.testing.strategies")
    return _with_hash(mech)


def redeclare(mech: Mechanism, body_order, joint_order) -> Mechanism:
    """The same mechanism with bodies and joints declared in another order.

    Parameters
    ----------
    mech : Mechanism
    body_order, joint_order : sequence of int
        Permutations of ``range(len(mech.bodies))`` and ``range(len(mech.joints))``: entry k is
        the old index of the new k-th body / joint.

    Returns
    -------
    Mechanism
        With its own ``content_hash`` (the harness caches the assembled start per hash).
    """
    changed = Mechanism(
        name=mech.name, kind=mech.kind,
        bodies=tuple(mech.bodies[i] for i in body_order),
        joints=tuple(mech.joints[i] for i in joint_order),
        forces=mech.forces, gravity=mech.gravity, initial=mech.initial, duration=mech.duration,
        outputs=mech.outputs, tags=mech.tags, notes=mech.notes, source=mech.source)
    return _with_hash(changed)


def _with_hash(mech: Mechanism) -> Mechanism:
    """``mech`` named and hashed by its :func:`~mbh._harness.model.mechanism.data_digest`."""
    digest = data_digest(mech)
    return Mechanism(**{**vars(mech), "name": f"generated-{digest[:12]}", "content_hash": digest})


@st.composite
def mechanisms(draw, planar: bool | None = None, allow_slender: bool = True,
               shuffle: bool = True) -> Mechanism:
    """A valid, assembled mechanism: a tree or a ladder, planar or spatial, loads and driver rate
    drawn, bodies and joints declared in a random order (unless ``shuffle`` is False).

    Parameters
    ----------
    planar : bool or None
        Force the kind; None draws it.
    allow_slender : bool
        Let bodies be slender (one principal moment zero).
    shuffle : bool
        Shuffle the declaration order of bodies and joints.
    """
    planar = draw(st.booleans()) if planar is None else planar
    family = draw(st.sampled_from([trees, ladders]))
    bodies, joints, driver = draw(family(planar, allow_slender))
    gravity = draw(_points(planar, spread=10.0))
    mech = Mechanism(
        name="generated", kind="planar" if planar else "spatial", bodies=bodies, joints=joints,
        forces=draw(_forces(bodies, joints, planar)), gravity=gravity,
        initial=InitialState(driver=driver, value=0.0,
                             rate=draw(st.sampled_from([-1.0, 1.0])) * draw(st.floats(0.2, 2.0))),
        duration=1.0, outputs=(), tags=("generated",), source="mbh._harness.testing.strategies")
    if shuffle:
        mech = redeclare(mech, draw(st.permutations(range(len(bodies)))),
                         draw(st.permutations(range(len(joints)))))
    return _with_hash(mech)
