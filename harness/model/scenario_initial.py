"""The ``[initial]`` section of a scenario file: the driver joint with its starting value and rate,
position guesses for bodies, and the velocities prescribed besides the driver's
(``[[initial.velocities]]``: a joint's rate, or a body point's velocity components).
"""

from __future__ import annotations

from mbh._harness.model.mechanism import (DRIVABLE, InitialState, Prescribed,
                                          PrescribedJointRate, PrescribedPointVelocity)
from mbh._harness.model.scenario_reader import COMPONENTS, ScenarioReader
from mbh._harness.model.toml_fields import _join, _missing

__all__ = ["read_initial"]

_INITIAL_KEYS = {"driver", "value", "rate", "guess", "velocities"}
_JOINT_RATE_KEYS = {"joint", "rate"}
_POINT_VELOCITY_KEYS = {"body", "location", "velocity", "components"}


def read_initial(reader: ScenarioReader) -> InitialState | None:
    """The ``[initial]`` section (the bodies and joints are read), or None when it has
    problems."""
    c = reader.c
    table = reader.doc.get("initial")
    if not isinstance(table, dict):
        c.add("initial", "missing required section [initial] with the driver")
        return None
    c.unknown_keys(table, _INITIAL_KEYS, "initial")
    driver = _drivable_joint(reader, table, "driver", "initial")
    value = c.number(table, "value", "initial", default=0.0)
    rate = c.number(table, "rate", "initial", default=0.0)
    guess = {}
    raw_guess = table.get("guess", {})
    if not isinstance(raw_guess, dict):
        c.add("initial.guess", "expected a table of body = [x, y, z]")
        raw_guess = {}
    for body in raw_guess:
        if body not in reader.bodies:
            c.add(f"initial.guess.{body}", f"unknown body {body!r}")
            continue
        point = c.vector(raw_guess, body, "initial.guess")
        if point is not None:
            guess[body] = point
    prescribed = _prescribed(reader, table, driver)
    if _missing(driver, value, rate, prescribed):
        return None
    return InitialState(driver, value, rate, guess, prescribed)


def _drivable_joint(reader: ScenarioReader, table: dict, key: str, path: str) -> str | None:
    """The joint named by ``table[key]`` if it exists and has a single coordinate."""
    name = reader.c.string(table, key, path)
    if name is None:
        return None
    return reader.known_joint(name, _join(path, key), DRIVABLE,
                              ", which has no single coordinate; drivable types: "
                              f"{', '.join(DRIVABLE)}")


def _prescribed(reader: ScenarioReader, table: dict,
                driver: str | None) -> tuple[Prescribed, ...] | None:
    """The ``[[initial.velocities]]`` entries, or None if any is invalid."""
    entries = table.get("velocities", [])
    if not isinstance(entries, list) or not all(isinstance(e, dict) for e in entries):
        reader.c.add("initial.velocities",
                     "expected an array of tables ([[initial.velocities]])")
        return None
    prescribed, valid, seen_joints = [], True, set()
    for index, entry in enumerate(entries):
        path = f"initial.velocities[{index}]"
        if ("joint" in entry) == ("body" in entry):
            reader.c.add(path, "give either joint (with rate) or body (with location and "
                         "velocity)")
            valid = False
            continue
        if "joint" in entry:
            item = _prescribed_rate(reader, entry, path, driver, seen_joints)
        else:
            item = _prescribed_point(reader, entry, path)
        valid = valid and item is not None
        prescribed.append(item)
    return tuple(prescribed) if valid else None


def _prescribed_rate(reader: ScenarioReader, entry: dict, path: str, driver: str | None,
                     seen: set[str]) -> PrescribedJointRate | None:
    """A joint's prescribed ``rate``: not the driver's, and not prescribed before (``seen``
    gathers the joints prescribed so far)."""
    reader.c.unknown_keys(entry, _JOINT_RATE_KEYS, path)
    joint = _drivable_joint(reader, entry, "joint", path)
    rate = reader.c.number(entry, "rate", path)
    if joint is not None and joint == driver:
        reader.c.add(_join(path, "joint"), f"joint {joint!r} is the driver; its rate is "
                     "initial.rate")
        return None
    if joint is not None and joint in seen:
        reader.c.add(_join(path, "joint"), f"joint {joint!r} is prescribed twice")
        return None
    if joint is not None:
        seen.add(joint)
    return None if _missing(joint, rate) else PrescribedJointRate(joint, rate)


def _prescribed_point(reader: ScenarioReader, entry: dict,
                      path: str) -> PrescribedPointVelocity | None:
    """A body point's prescribed velocity (world coordinates), in the given components."""
    c = reader.c
    c.unknown_keys(entry, _POINT_VELOCITY_KEYS, path)
    body = reader.moving_body(entry, path)
    location = reader.planar_point(entry, "location", path)
    velocity = reader.planar_point(entry, "velocity", path)
    components = _components(reader, entry, path)
    if _missing(body, location, velocity, components):
        return None
    return PrescribedPointVelocity(body, reader.local_point(body, location), velocity,
                                   components)


def _components(reader: ScenarioReader, entry: dict, path: str) -> tuple[int, ...] | None:
    """The indices of the ``components`` a point velocity prescribes (default: all the scene
    has)."""
    letters = ("x", "y") if reader.planar else ("x", "y", "z")
    raw = entry.get("components", list(letters))
    field = _join(path, "components")
    if (not isinstance(raw, list) or not raw
            or not all(isinstance(letter, str) and letter in letters for letter in raw)
            or len(set(raw)) != len(raw)):
        reader.c.add(field, f"expected a non-empty list of distinct components from "
                     f"{', '.join(letters)}, got {raw!r}")
        return None
    return tuple(COMPONENTS[letter] for letter in raw)
