"""The ``[[forces]]`` of a scenario file: joint torques and forces, forces and torques on bodies,
and spring-dampers between two body points.
"""

from __future__ import annotations

import numpy as np

from mbh._harness.model.mechanism import (GROUND, BodyForce, BodyTorque, JointActuation,
                                          SpringDamper)
from mbh._harness.model.scenario_reader import ScenarioReader
from mbh._harness.model.toml_fields import _join, _missing

__all__ = ["read_forces"]

#: The keys of each force type (docs/formats/scenario.md, "[[forces]]").
_FORCE_KEYS = {
    "joint_torque": {"type", "joint", "value"},
    "joint_force": {"type", "joint", "value"},
    "body_force": {"type", "body", "force", "point"},
    "body_torque": {"type", "body", "torque"},
    "spring_damper": {"type", "name", "body1", "body2", "location1", "location2", "stiffness",
                      "damping", "free_length"},
}


def read_forces(reader: ScenarioReader) -> list:
    """The ``[[forces]]`` (the bodies and joints are read), each valid one as its
    :mod:`~mbh._harness.model.mechanism` load."""
    c = reader.c
    forces = []
    for path, table in reader.tables("forces", required=False):
        ftype = c.string(table, "type", path)
        if ftype is None:
            continue
        if ftype not in _FORCE_KEYS:
            c.add(_join(path, "type"), f"unknown force type {ftype!r} "
                  f"(known: {', '.join(sorted(_FORCE_KEYS))})")
            continue
        c.unknown_keys(table, _FORCE_KEYS[ftype], path)
        force = _READERS[ftype](reader, table, path)
        if force is not None:
            forces.append(force)
    return forces


# Each reader below takes one force type's table and returns its load, or None with the
# problems added.
def _joint_torque(reader: ScenarioReader, table, path):
    joint = reader.joint_ref(table, path, types=("revolute", "cylindrical"))
    value = reader.c.number(table, "value", path)
    return None if _missing(joint, value) else JointActuation(joint, value)


def _joint_force(reader: ScenarioReader, table, path):
    joint = reader.joint_ref(table, path, types=("prismatic", "translational", "cylindrical"))
    value = reader.c.number(table, "value", path)
    return None if _missing(joint, value) else JointActuation(joint, value)


def _body_force(reader: ScenarioReader, table, path):
    body = reader.body_ref(table, "body", path)
    force = reader.c.vector(table, "force", path)
    point = reader.c.vector(table, "point", path, required=False)
    if _missing(body, force) or body == GROUND or reader.bodies[body] is None:
        return None
    local = np.zeros(3) if point is None else reader.local_point(body, point)
    return BodyForce(body, force, local)


def _body_torque(reader: ScenarioReader, table, path):
    body = reader.body_ref(table, "body", path)
    torque = reader.c.vector(table, "torque", path)
    return None if _missing(body, torque) or body == GROUND else BodyTorque(body, torque)


def _spring_damper(reader: ScenarioReader, table, path):
    c = reader.c
    name = c.name(table, "name", path, default="spring")
    body1 = reader.body_ref(table, "body1", path)
    body2 = reader.body_ref(table, "body2", path)
    loc1 = c.vector(table, "location1", path)
    loc2 = c.vector(table, "location2", path)
    k = c.number(table, "stiffness", path, nonnegative=True)
    d = c.number(table, "damping", path, default=0.0, nonnegative=True)
    length = c.number(table, "free_length", path, nonnegative=True)
    if _missing(name, body1, body2, loc1, loc2, k, d, length) \
            or reader.bodies.get(body1, 0) is None or reader.bodies.get(body2, 0) is None:
        return None
    return SpringDamper(name, body1, body2, reader.local_point(body1, loc1),
                        reader.local_point(body2, loc2), k, d, length)


#: The reader of each force type (the keys of :data:`_FORCE_KEYS`).
_READERS = {"joint_torque": _joint_torque, "joint_force": _joint_force,
            "body_force": _body_force, "body_torque": _body_torque,
            "spring_damper": _spring_damper}
