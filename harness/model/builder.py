"""Build a mechanism in Python, with the scenario file's own sections and fields.

:class:`MechanismBuilder` collects the same document a scenario file parses to — top-level fields,
``[[bodies]]``, ``[[joints]]``, ``[[forces]]``, ``[initial]``, ``[outputs]``, ``[reference]``,
with the field names, units and conventions of docs/formats/scenario.md — and hands it to the file
loader's validator (:func:`harness.model.scenario.from_document`).  A mechanism built here
therefore obeys the same rules, fails with the same :class:`~harness.model.scenario.ScenarioError`
(every problem, each naming the field), and has the same ``content_hash`` as a file holding the
same document: the reference and result caches cannot tell them apart, and two different
mechanisms never share a reference.

The hash is of the values as given, like a file's: ``mass=1`` (an integer) and ``mass=1.0`` are
different documents, as ``mass = 1`` and ``mass = 1.0`` are in TOML.  numpy arrays and scalars
and tuples are turned into the lists and numbers a TOML file would hold.  The name is not part
of the document (a file's name is its stem), so ``MechanismBuilder("arm", ...)`` and ``arm.toml``
hash alike.
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np

from harness.model.mechanism import Mechanism
from harness.model.scenario import from_document


def _plain(value: Any) -> Any:
    """``value`` as a TOML parser would return it: lists for arrays and tuples, Python numbers
    for numpy scalars, dicts and lists converted all the way down."""
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, (list, tuple)):
        return [_plain(item) for item in value]
    if isinstance(value, dict):
        return {key: _plain(item) for key, item in value.items()}
    return value


class MechanismBuilder:
    """A scenario document assembled call by call; :meth:`build` validates it.

    Parameters
    ----------
    name : str
        The mechanism's name (a file's stem).
    **fields
        Top-level fields: ``kind`` ("planar" or "spatial"), ``plane`` ("xy", planar only),
        ``duration`` (s), ``gravity`` (m/s², shape (3,)), and optionally ``sample_step`` (s),
        ``tags``, ``notes``.

    Examples
    --------
    A pendulum: a 1 kg bar of 1 m swinging about its end, released horizontal.

    >>> from harness.model.builder import MechanismBuilder
    >>> pendulum = (MechanismBuilder("bar_pendulum", kind="planar", plane="xy", duration=1.0,
    ...                              gravity=[0.0, -9.81, 0.0])
    ...             .body("bar", mass=1.0, inertia=[0.0, 1 / 12, 1 / 12], position=[0.5, 0.0, 0.0])
    ...             .joint("pivot", "revolute", body1="ground", body2="bar", location=[0.0, 0.0, 0.0])
    ...             .initial(driver="pivot", value=0.0, rate=0.0)
    ...             .output("angle", "joint_angle", joint="pivot")
    ...             .build())
    >>> pendulum.name, len(pendulum.bodies), pendulum.outputs[0].name
    ('bar_pendulum', 1, 'angle')
    """

    def __init__(self, name: str, **fields: Any):
        self.name = name
        self._document: dict[str, Any] = _plain(fields)

    def _append(self, section: str, table: dict) -> "MechanismBuilder":
        self._document.setdefault(section, []).append(_plain(table))
        return self

    def body(self, name: str, **fields: Any) -> "MechanismBuilder":
        """Add a ``[[bodies]]`` entry: ``mass`` (kg) and ``inertia`` (kg·m², about the centre of
        mass) or ``parts``, ``position`` (m) and an orientation, as in a file."""
        return self._append("bodies", {"name": name, **fields})

    def joint(self, name: str, type: str, **fields: Any) -> "MechanismBuilder":
        """Add a ``[[joints]]`` entry of ``type`` (revolute, spherical, ...): ``body1``,
        ``body2``, ``location`` (m, world, at the start), ``axis`` ... as in a file."""
        return self._append("joints", {"name": name, "type": type, **fields})

    def force(self, type: str, **fields: Any) -> "MechanismBuilder":
        """Add a ``[[forces]]`` entry of ``type`` (joint_torque, spring_damper, ...)."""
        return self._append("forces", {"type": type, **fields})

    def initial(self, **fields: Any) -> "MechanismBuilder":
        """Set the ``[initial]`` table: ``driver``, ``value``, ``rate``, ``guess``, ..."""
        self._document["initial"] = _plain(fields)
        return self

    def output(self, name: str, kind: str, **fields: Any) -> "MechanismBuilder":
        """Add output ``name`` of ``kind`` (joint_angle, position, point_velocity, ...) to the
        ``[outputs]`` table; the first output is the main one."""
        self._document.setdefault("outputs", {})[name] = _plain({"kind": kind, **fields})
        return self

    def reference(self, **fields: Any) -> "MechanismBuilder":
        """Set the ``[reference]`` table (``equal_joint_angles``, ``routes``)."""
        self._document["reference"] = _plain(fields)
        return self

    def document(self) -> dict:
        """A copy of the document as built so far (what a scenario file would parse to)."""
        return copy.deepcopy(self._document)

    def build(self) -> Mechanism:
        """The validated mechanism.

        Raises
        ------
        ScenarioError
            With every problem found, each naming ``<python: NAME>`` and the field.
        """
        return from_document(self.document(), self.name, f"<python: {self.name}>")
