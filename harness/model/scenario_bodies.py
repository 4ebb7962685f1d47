"""The ``[[bodies]]`` of a scenario file: each body's mass, centroidal inertia, centre of mass and
orientation, as written or summed from its ``parts`` (:mod:`mbh._harness.model.parts`), and the
check, once the joints are read, that the joints hold every turn a body has no inertia against
(:mod:`mbh._harness.model.free_turns`).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from mbh._harness.model import parts as shapes
from mbh._harness.model.free_turns import ZERO_MOMENT, free_turn
from mbh._harness.model.mechanism import GROUND, Body
from mbh._harness.model.scenario_reader import ScenarioReader
from mbh._harness.model.toml_fields import LARGEST, SMALLEST, _join, _missing

__all__ = ["inertia_tensor", "inertia_problem", "read_bodies", "check_held_turns"]

_BODY_KEYS = {"name", "mass", "inertia", "position", "angle_deg", "euler313_deg", "quaternion",
              "parts"}
#: What a body of parts does not take: the loader computes them from its parts.
_COMPUTED_FROM_PARTS = ("mass", "inertia", "position")
_ORIENTATION_KEYS = {"angle_deg", "euler313_deg", "quaternion"}
#: The keys of each part type (docs/formats/scenario.md, "Parts").
_PART_KEYS = {
    "point": {"type", "mass", "position"},
    "rod": {"type", "mass", "density", "position", "axis", "length"},
    "box": {"type", "mass", "density", "position", "size"} | _ORIENTATION_KEYS,
    "cylinder": {"type", "mass", "density", "position", "axis", "radius", "length"},
    "sphere": {"type", "mass", "density", "position", "radius"},
}
#: Unit of each part type's density: per length for a rod, per volume for the solids.
_DENSITY_UNIT = {"rod": "kg/m", "box": "kg/m³", "cylinder": "kg/m³", "sphere": "kg/m³"}


def inertia_tensor(values: np.ndarray) -> np.ndarray:
    """Inertia tensor from ``[Ixx, Iyy, Izz]`` or ``[Ixx, Iyy, Izz, Ixy, Ixz, Iyz]`` (kg·m²)."""
    if len(values) == 3:
        return np.diag(values)
    ixx, iyy, izz, ixy, ixz, iyz = values
    return np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])


def inertia_problem(tensor: np.ndarray) -> str | None:
    """Why ``tensor`` is not a physical inertia tensor, or None.

    Accepts a positive definite tensor obeying the triangle inequality, a slender bar's: one
    principal moment zero (below :data:`~mbh._harness.model.free_turns.ZERO_MOMENT` of the
    trace), the other two equal (the triangle inequality with equality), or a point mass's: all
    three zero.  Whether the joints hold the turns such a body has no inertia against is checked
    with the joints (:mod:`mbh._harness.model.free_turns`).
    """
    principal = np.linalg.eigvalsh(tensor)
    total = principal.sum()
    zero = ZERO_MOMENT * abs(total)
    listed = f"(principal moments {principal.tolist()})"
    if principal[0] < -zero:
        return f"has a negative principal moment {listed}"
    if principal[2] <= zero:
        return None  # a point mass
    if principal[1] <= zero:
        return (f"has two zero principal moments {listed}; only a slender bar (one zero moment, "
                "about its axis) or a point mass (all three zero) may have any")
    for moment in principal:
        if moment > total - moment + ZERO_MOMENT * total:
            return ("breaks the triangle inequality: principal moment "
                    f"{moment:g} exceeds the sum of the other two ({total - moment:g})")
    return None


def read_bodies(reader: ScenarioReader) -> dict[str, str]:
    """Read the ``[[bodies]]`` into ``reader.bodies``.

    Returns
    -------
    dict
        The field of each valid body's inertia, by name (where :func:`check_held_turns` names
        a free turn).
    """
    c = reader.c
    inertia_fields: dict[str, str] = {}
    for path, table in reader.tables("bodies", required=True):
        c.unknown_keys(table, _BODY_KEYS, path)
        name = reader.unique_name(table, path, reader.bodies, reserved=(GROUND,))
        rotation = _orientation(reader, table, path)
        if "parts" in table:
            mass, inertia, position = _body_of_parts(reader, table, path, rotation)
        else:
            mass, inertia, position = _body_given(reader, table, path)
        if not _missing(name, mass, inertia, position, rotation):
            reader.bodies[name] = Body(name, mass, inertia, position, rotation)
            inertia_fields[name] = _join(path, "parts" if "parts" in table else "inertia")
        elif name is not None:
            reader.bodies[name] = None  # known name, invalid body: keeps references quiet
    return inertia_fields


def _body_given(reader: ScenarioReader, table: dict, path: str) -> tuple:
    """(mass kg, centroidal inertia (3, 3) in the body frame, centre of mass (3,) m) as
    written, each None where invalid."""
    c = reader.c
    mass = c.number(table, "mass", path, positive=True)
    inertia_values = c.vector(table, "inertia", path, length=(3, 6))
    inertia = None
    if inertia_values is not None:
        inertia = inertia_tensor(inertia_values)
        problem = inertia_problem(inertia)
        if problem:
            c.add(_join(path, "inertia"), problem)
            inertia = None
    position = c.vector(table, "position", path)
    if reader.planar and position is not None and position[2] != 0.0:
        c.add(_join(path, "position"), "a planar body must lie in z = 0")
    return mass, inertia, position


def _body_of_parts(reader: ScenarioReader, table: dict, path: str,
                   rotation: np.ndarray | None) -> tuple:
    """(mass kg, centroidal inertia (3, 3) in the body frame of ``rotation``, centre of
    mass (3,) m) of the body's ``parts`` (:mod:`mbh._harness.model.parts`), or Nones."""
    c = reader.c
    for key in _COMPUTED_FROM_PARTS:
        if key in table:
            c.add(_join(path, key), "not with parts: the mass, centre of mass and inertia "
                  "of a body of parts are computed from its parts")
    field = _join(path, "parts")
    entries = table["parts"]
    if not isinstance(entries, list) or not entries \
            or not all(isinstance(entry, dict) for entry in entries):
        c.add(field, "expected a non-empty array of tables, one per part "
              "([[bodies.parts]] or a list of inline tables)")
        return None, None, None
    found = [_part(reader, entry, f"{field}[{index}]") for index, entry in enumerate(entries)]
    if _missing(*found):
        return None, None, None
    whole = shapes.combined(found)
    if not (np.all(np.isfinite(whole.inertia)) and np.abs(whole.inertia).max() <= LARGEST
            and whole.mass <= LARGEST):
        c.add(field, f"the parts' mass or inertia exceeds the limit {LARGEST:g}")
        return None, None, None
    inertia = None if rotation is None else rotation.T @ whole.inertia @ rotation
    return whole.mass, inertia, whole.centre


def _part(reader: ScenarioReader, table: dict, path: str) -> shapes.MassProperties | None:
    """One part: its type, placement and size, and its mass or density."""
    c = reader.c
    kind = c.string(table, "type", path)
    if kind is None:
        return None
    if kind not in _PART_KEYS:
        c.add(_join(path, "type"), f"unknown part type {kind!r} "
              f"(known: {', '.join(_PART_KEYS)})")
        return None
    c.unknown_keys(table, _PART_KEYS[kind], path)
    centre = reader.planar_point(table, "position", path)
    shape = _SHAPES[kind](reader, table, path)  # (measure, mass → part) or None
    mass = _part_mass(reader, table, path, kind, None if shape is None else shape[0])
    if _missing(centre, shape, mass):
        return None
    return shape[1](mass, centre)


def _part_mass(reader: ScenarioReader, table: dict, path: str, kind: str,
               measure: float | None) -> float | None:
    """The part's ``mass`` (kg), or ``density`` times its ``measure`` (length m or volume
    m³); a point takes mass only."""
    c = reader.c
    if "mass" in table and "density" in table:
        c.add(path, "give mass or density, not both")
        return None
    if "mass" in table or kind == "point":  # a point's density is an unknown key
        return c.number(table, "mass", path, positive=True)
    if "density" not in table:
        c.add(_join(path, "mass"), f"missing: give mass (kg) or density "
              f"({_DENSITY_UNIT[kind]})")
        return None
    density = c.number(table, "density", path, positive=True)
    if density is None or measure is None:
        return None
    mass = density * measure
    if not SMALLEST <= mass <= LARGEST:
        c.add(_join(path, "density"), f"gives a mass of {mass:g} kg, outside "
              f"[{SMALLEST:g}, {LARGEST:g}]")
        return None
    return mass


# Each _<type>_shape reads the type's size keys and returns (measure: length m or volume m³,
# a function of (mass kg, centre (3,) m) giving the part), or None with the problems added.
def _point_shape(reader: ScenarioReader, table, path):
    return 0.0, shapes.point


def _rod_shape(reader: ScenarioReader, table, path):
    length = reader.c.number(table, "length", path, positive=True)
    axis = reader.c.vector(table, "axis", path, nonzero=True)
    if _missing(length, axis):
        return None
    return length, lambda mass, centre: shapes.rod(mass, length, centre, axis)


def _box_shape(reader: ScenarioReader, table, path):
    size = reader.c.vector(table, "size", path)
    if size is not None and not np.all(size > 0.0):
        reader.c.add(_join(path, "size"), f"edge lengths must be > 0, got {size.tolist()}")
        size = None
    rotation = _orientation(reader, table, path, "box")
    if _missing(size, rotation):
        return None
    return (shapes.box_volume(size),
            lambda mass, centre: shapes.box(mass, size, centre, rotation))


def _cylinder_shape(reader: ScenarioReader, table, path):
    radius = reader.c.number(table, "radius", path, positive=True)
    length = reader.c.number(table, "length", path, positive=True)
    axis = reader.c.vector(table, "axis", path, nonzero=True)
    if _missing(radius, length, axis):
        return None
    return (shapes.cylinder_volume(radius, length),
            lambda mass, centre: shapes.cylinder(mass, radius, length, centre, axis))


def _sphere_shape(reader: ScenarioReader, table, path):
    radius = reader.c.number(table, "radius", path, positive=True)
    if radius is None:
        return None
    return (shapes.sphere_volume(radius),
            lambda mass, centre: shapes.sphere(mass, radius, centre))


def _orientation(reader: ScenarioReader, table: dict, path: str,
                 what: str = "body") -> np.ndarray | None:
    """The rotation (3, 3) a body or box is given by (``what`` names it in problems)."""
    c = reader.c
    given = [k for k in ("angle_deg", "euler313_deg", "quaternion") if k in table]
    if len(given) > 1:
        c.add(path, f"give one orientation, not {', '.join(given)}")
        return None
    if reader.planar:
        if given and given[0] != "angle_deg":
            c.add(_join(path, given[0]), f"a planar {what} takes angle_deg")
            return None
        angle = c.number(table, "angle_deg", path, default=0.0)
        return None if angle is None else Rotation.from_euler("z", angle, degrees=True).as_matrix()
    if not given:
        return np.eye(3)
    if given[0] == "euler313_deg":
        angles = c.vector(table, "euler313_deg", path)
        return (None if angles is None
                else Rotation.from_euler("ZXZ", angles, degrees=True).as_matrix())
    if given[0] == "quaternion":
        quat = c.vector(table, "quaternion", path, length=(4,), nonzero=True)
        return None if quat is None else Rotation.from_quat(quat, scalar_first=True).as_matrix()
    c.add(_join(path, "angle_deg"), f"a spatial {what} takes euler313_deg or quaternion")
    return None


def check_held_turns(reader: ScenarioReader, inertia_fields: dict[str, str]) -> None:
    """Every body with zero principal moments must have the turns about those axes held by
    its joints (:mod:`mbh._harness.model.free_turns`); a problem is recorded at the body's field
    in ``inertia_fields`` (from :func:`read_bodies`).  Skipped while a joint has problems: a free
    turn would then only echo them."""
    joints = [joint for joint in reader.joints.values() if joint is not None]
    tables = reader.doc.get("joints")
    if not isinstance(tables, list) or len(joints) != len(tables):
        return
    for name, body in reader.bodies.items():
        turn = None if body is None else free_turn(body, joints, reader.planar)
        if turn is not None:
            reader.c.add(inertia_fields[name], (
                f"body {name!r} has no inertia about the axis {np.round(turn, 12).tolist()} "
                f"through its centre of mass {body.position.tolist()} and its joints leave "
                "that turn free, so its motion is undetermined; tie it by a joint at a point "
                "away from the centre of mass (a revolute whose axis misses it; a spherical "
                "joint leaves the turn about the line to the joint free)"))


#: The size reader of each part type (the keys of :data:`_PART_KEYS`).
_SHAPES = {"point": _point_shape, "rod": _rod_shape, "box": _box_shape,
           "cylinder": _cylinder_shape, "sphere": _sphere_shape}
