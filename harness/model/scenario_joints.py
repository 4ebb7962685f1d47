"""The ``[[joints]]`` of a scenario file: each joint's type, bodies, location, axes and normal,
checked against the scene's kind and put in the frames of the bodies it connects.
"""

from __future__ import annotations

import numpy as np

from mbh._harness.model.mechanism import GROUND, JOINT_TYPES, PLANAR_JOINT_TYPES, Joint
from mbh._harness.model.scenario_reader import ScenarioReader
from mbh._harness.model.toml_fields import _join, _missing

__all__ = ["read_joints"]

_JOINT_KEYS = {"name", "type", "body1", "body2", "location", "location2", "axis", "axis2", "normal"}


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _perpendicular(axis: np.ndarray) -> np.ndarray:
    """A unit vector perpendicular to ``axis`` (deterministic choice)."""
    trial = np.eye(3)[int(np.argmin(np.abs(axis)))]
    return _unit(trial - axis * (trial @ axis))


def read_joints(reader: ScenarioReader) -> None:
    """Read the ``[[joints]]`` into ``reader.joints`` (the bodies are read)."""
    c = reader.c
    for path, table in reader.tables("joints", required=True):
        c.unknown_keys(table, _JOINT_KEYS, path)
        name = reader.unique_name(table, path, reader.joints)
        jtype = c.string(table, "type", path)
        allowed = PLANAR_JOINT_TYPES if reader.planar else JOINT_TYPES
        if jtype is not None and jtype not in allowed:
            kind = "planar" if reader.planar else "spatial"
            c.add(_join(path, "type"), f"unknown {kind} joint type {jtype!r} "
                  f"(known: {', '.join(allowed)})")
            jtype = None
        body1 = reader.body_ref(table, "body1", path)
        body2 = reader.body_ref(table, "body2", path)
        if body1 is not None and body1 == body2:
            c.add(_join(path, "body2"),
                  f"a joint needs two different bodies, got {body1!r} twice")
            body2 = None
        location = c.vector(table, "location", path)
        location2 = c.vector(table, "location2", path, required=False)
        needs_axis = (jtype not in (None, "spherical")
                      and not (reader.planar and jtype == "revolute"))
        axis = c.vector(table, "axis", path, required=needs_axis, nonzero=True)
        axis2 = c.vector(table, "axis2", path, required=jtype == "universal", nonzero=True)
        normal = c.vector(table, "normal", path, required=False, nonzero=True)
        if reader.planar:
            axis = _planar_axis(reader, jtype, axis, path)
            for key, point in (("location", location), ("location2", location2)):
                if point is not None and point[2] != 0.0:
                    c.add(_join(path, key), "a planar joint must lie in z = 0")
        if jtype == "spherical" and axis is None:
            axis = np.array([0.0, 0.0, 1.0])
        if jtype == "universal" and axis is not None and axis2 is not None:
            if abs(_unit(axis) @ _unit(axis2)) > 1e-9:
                c.add(_join(path, "axis2"),
                      "the universal joint's cross axes must be perpendicular")
                axis2 = None
        if normal is not None and axis is not None and abs(_unit(normal) @ _unit(axis)) > 1e-9:
            c.add(_join(path, "normal"), "must be perpendicular to the axis")
            normal = None
        parts = (name, jtype, body1, body2, location, axis)
        if _missing(*parts) or (jtype == "universal" and axis2 is None) \
                or reader.bodies.get(body1, 0) is None or reader.bodies.get(body2, 0) is None:
            if name is not None:
                reader.joints[name] = None
            continue
        reader.joints[name] = _joint(reader, name, jtype, body1, body2, location, location2,
                                     _unit(axis), None if axis2 is None else _unit(axis2),
                                     None if normal is None else _unit(normal))


def _planar_axis(reader: ScenarioReader, jtype, axis, path) -> np.ndarray | None:
    """The axis of a planar joint: z for a revolute (the default), in the x–y plane for a
    prismatic; None when the given axis breaks that."""
    z = np.array([0.0, 0.0, 1.0])
    if jtype == "revolute":
        if axis is not None and np.linalg.norm(np.cross(_unit(axis), z)) > 1e-9:
            reader.c.add(_join(path, "axis"), "a planar revolute joint turns about z")
            return None
        return z if axis is None else _unit(axis)
    if axis is not None and abs(axis[2]) > 0:
        reader.c.add(_join(path, "axis"), "a planar prismatic axis must lie in the x–y plane")
        return None
    return axis


def _joint(reader: ScenarioReader, name, jtype, body1, body2, location, location2, axis, axis2,
           normal) -> Joint:
    """The joint from its checked fields (world coordinates, unit axes), with its points and
    directions put in each body's frame."""
    point1 = reader.local_point(body1, location)
    point2 = reader.local_point(body2, location if location2 is None else location2)
    if jtype == "universal":
        normal = np.cross(axis, axis2)
        second = axis2
    else:
        second = axis
        # A given normal passed the 1e-9 perpendicularity check; project it exactly, so the
        # joint's frame is orthonormal to round-off (engines in joint coordinates need it).
        normal = (_perpendicular(axis) if normal is None
                  else _unit(normal - (normal @ axis) * axis))
    return Joint(
        name=name, type=jtype, body1=body1, body2=body2, point1=point1, point2=point2,
        axis1=_local_direction(reader, body1, axis),
        axis2=_local_direction(reader, body2, second),
        normal1=_local_direction(reader, body1, normal),
        normal2=_local_direction(reader, body2, normal),
    )


def _local_direction(reader: ScenarioReader, body: str, world: np.ndarray) -> np.ndarray:
    """The direction ``world`` (3,), given in world coordinates, in the frame of ``body``."""
    return world.copy() if body == GROUND else reader.bodies[body].rotation.T @ world
