"""One scenario document being read: where its problems are collected, whether the scene is
planar, the bodies and joints read so far, and the look-ups its sections share (a body or joint
named by a field, a point written in world coordinates put in a body's frame).

The sections are read by :mod:`~mbh._harness.model.scenario_bodies`,
:mod:`~mbh._harness.model.scenario_joints`, :mod:`~mbh._harness.model.scenario_forces`,
:mod:`~mbh._harness.model.scenario_initial` and :mod:`~mbh._harness.model.scenario_outputs`, in
the order :func:`mbh._harness.model.scenario.from_document` calls them.
"""

from __future__ import annotations

import numpy as np

from mbh._harness.model.mechanism import GROUND, Body, Joint
from mbh._harness.model.toml_fields import _Collector, _join

__all__ = ["COMPONENTS", "ScenarioReader"]

#: Index of each coordinate a component letter names.
COMPONENTS = {"x": 0, "y": 1, "z": 2}


class ScenarioReader:
    """What the sections of one scenario document share while it is read.

    Parameters
    ----------
    c : _Collector
        Where the problems found are recorded, each with the file and the field.
    document : dict
        The document (a parsed scenario file).
    planar : bool
        Whether the scene is planar (``kind = "planar"``).

    Attributes
    ----------
    bodies : dict
        Each body read so far by name, in file order; None for a named body with problems (a
        reference to it then adds no second problem).
    joints : dict
        Each joint read so far by name, the same way.
    """

    def __init__(self, c: _Collector, document: dict, planar: bool):
        self.c = c
        self.doc = document
        self.planar = planar
        self.bodies: dict[str, Body | None] = {}
        self.joints: dict[str, Joint | None] = {}

    def tables(self, key: str, required: bool) -> list[tuple[str, dict]]:
        """(field path, table) of each entry of the array of tables ``key`` (``[[key]]``); a
        missing ``required`` section, or one that holds no entry, is a problem."""
        items = self.doc.get(key)
        if items is None:
            if required:
                self.c.add(key, "missing required section")
            return []
        if not isinstance(items, list) or not all(isinstance(t, dict) for t in items):
            self.c.add(key, f"expected an array of tables ([[{key}]])")
            return []
        if required and not items:
            self.c.add(key, "must hold at least one entry")
        return [(f"{key}[{i}]", table) for i, table in enumerate(items)]

    def unique_name(self, table: dict, path: str, seen: dict, reserved=()) -> str | None:
        """``table["name"]`` if it names nothing in ``seen`` or ``reserved``, else None."""
        name = self.c.name(table, "name", path)
        if name is None:
            return None
        if name in seen or name in reserved:
            self.c.add(_join(path, "name"), f"duplicate name {name!r}")
            return None
        return name

    def body_ref(self, table: dict, key: str, path: str) -> str | None:
        """The body (or ground) named by ``table[key]`` if it is declared, else None."""
        name = self.c.string(table, key, path)
        if name is None or name == GROUND:
            return name
        if name not in self.bodies:
            known = ", ".join([GROUND, *self.bodies])
            self.c.add(_join(path, key), f"unknown body {name!r} (known: {known})")
            return None
        return name

    def moving_body(self, table: dict, path: str) -> str | None:
        """A known, valid, non-ground body named by ``table["body"]``."""
        body = self.body_ref(table, "body", path)
        if body == GROUND:
            self.c.add(_join(path, "body"), "ground does not move; name a body")
            return None
        if body is None or self.bodies[body] is None:
            return None
        return body

    def planar_point(self, table: dict, key: str, path: str) -> np.ndarray | None:
        """A 3-vector; in a planar scene its z component must be 0."""
        point = self.c.vector(table, key, path)
        if self.planar and point is not None and point[2] != 0.0:
            self.c.add(_join(path, key), "a planar scene lies in z = 0")
            return None
        return point

    def local_point(self, body: str, world: np.ndarray) -> np.ndarray:
        """The point ``world`` (3,) m, given in world coordinates, in the frame of ``body``."""
        if body == GROUND:
            return world.copy()
        b = self.bodies[body]
        return b.rotation.T @ (world - b.position)

    def known_joint(self, name: str, field: str, types=(), rule: str = "") -> str | None:
        """``name`` if it is a declared joint whose type is among ``types`` (any when empty);
        else None, with the problem recorded at ``field`` (``rule`` says what was expected)."""
        if name not in self.joints:
            self.c.add(field, f"unknown joint {name!r} (known: {', '.join(self.joints)})")
            return None
        joint = self.joints[name]
        if types and joint is not None and joint.type not in types:
            self.c.add(field, f"joint {name!r} is {joint.type}{rule}")
            return None
        return name

    def joint_ref(self, table: dict, path: str, types=()) -> str | None:
        """The joint named by ``table["joint"]`` (see :meth:`known_joint`), or None."""
        name = self.c.string(table, "joint", path)
        if name is None:
            return None
        return self.known_joint(name, _join(path, "joint"), types,
                                f"; expected one of {', '.join(types)}")
