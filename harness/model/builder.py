"""Build a mechanism in Python, with the scenario file's own sections and fields.

:class:`MechanismBuilder` collects the same document a scenario file parses to — top-level fields,
``[[bodies]]``, ``[[joints]]``, ``[[forces]]``, ``[initial]``, ``[outputs]``, ``[reference]``,
with the field names, units and conventions of docs/formats/scenario.md — and hands it to the file
loader's validator (:func:`mbh._harness.model.scenario.from_document`).  A mechanism built here
therefore obeys the same rules, fails with the same :class:`~mbh._harness.model.scenario.ScenarioError`
(every problem, each naming the field), and has the same ``content_hash`` as a file holding the
same document: the reference and result caches cannot tell them apart, and two different
mechanisms never share a reference.

The hash is of the values as given, like a file's: ``mass=1`` (an integer) and ``mass=1.0`` are
different documents, as ``mass = 1`` and ``mass = 1.0`` are in TOML.  numpy arrays and scalars
and tuples are turned into the lists and numbers a TOML file would hold; what no file can hold —
a key that is not a string, an integer beyond 64 bits, containers nested deeper than
:data:`MAX_DEPTH` (a list holding itself, say) — is a problem :meth:`MechanismBuilder.build`
names like any other.  The name is not part
of the document (a file's name is its stem), so ``MechanismBuilder("arm", ...)`` and ``arm.toml``
hash alike.
"""

from __future__ import annotations

from typing import Any, Iterator

import numpy as np

from mbh._harness.model.mechanism import Mechanism
from mbh._harness.model.scenario import ScenarioError, from_document
from mbh._harness.model.toml_fields import Problem, _join, _key_text

#: Deepest nesting of lists and tables a built document may have; a scenario's deepest field,
#: ``initial.velocities[i].location``, is 4 deep.
MAX_DEPTH = 32
#: TOML integers are 64-bit signed.
_INTEGER_BITS = 63


def _plain(value: Any, depth: int = 0) -> Any:
    """``value`` as a TOML parser would return it: lists for arrays and tuples, Python numbers
    for numpy scalars, dicts and lists converted (and so copied) all the way down to
    :data:`MAX_DEPTH`; anything else as it is (the validator names what is wrong with it)."""
    if depth > MAX_DEPTH:
        return value
    if isinstance(value, np.ndarray):
        return _plain(value.tolist(), depth)
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, (list, tuple)):
        return [_plain(item, depth + 1) for item in value]
    if isinstance(value, dict):
        return {key: _plain(item, depth + 1) for key, item in value.items()}
    return value


def _unrepresentable(value: Any, field: str, depth: int = 0) -> Iterator[tuple[str, str]]:
    """(field, problem) for every part of a :func:`_plain` document no TOML file can hold."""
    if depth > MAX_DEPTH:
        yield field, f"nested deeper than {MAX_DEPTH} levels of lists and tables"
    elif isinstance(value, int) and not isinstance(value, bool) \
            and value.bit_length() > _INTEGER_BITS:
        yield field, (f"an integer of {value.bit_length()} bits; a scenario holds 64-bit "
                      f"integers (use a float)")
    elif isinstance(value, list):
        for index, item in enumerate(value):
            yield from _unrepresentable(item, f"{field}[{index}]", depth + 1)
    elif isinstance(value, dict):
        for key, item in value.items():
            if isinstance(key, str):
                yield from _unrepresentable(item, _join(field, _key_text(key)), depth + 1)
            else:
                yield field or "-", (f"a key of type {type(key).__name__}; keys are strings, "
                                     f"as in a scenario file")


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

    >>> from mbh._harness.model.builder import MechanismBuilder
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
        #: Entries added by calls, per section (outputs as (name, table) pairs); merged into the
        #: document by :meth:`document`, which names a section also given as a field.
        self._added: dict[str, list] = {"bodies": [], "joints": [], "forces": [], "outputs": []}

    def _append(self, section: str, entry) -> "MechanismBuilder":
        self._added[section].append(_plain(entry))
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
        return self._append("outputs", (name, {"kind": kind, **fields}))

    def reference(self, **fields: Any) -> "MechanismBuilder":
        """Set the ``[reference]`` table (``equal_joint_angles``, ``routes``)."""
        self._document["reference"] = _plain(fields)
        return self

    @property
    def source(self) -> str:
        """How problems name the mechanism: ``<python: NAME>`` (a name that is not a string by
        its type: its text may not even be printable, as for an integer of 5000 digits)."""
        name = self.name if isinstance(self.name, str) else f"a {type(self.name).__name__}"
        return f"<python: {name}>"

    def document(self) -> dict:
        """A copy of the document as built so far (what a scenario file would parse to).

        Raises
        ------
        ScenarioError
            When part of it is nothing a scenario file can hold (see the module docstring).
        """
        source = self.source
        document, clashes = self._merged()
        problems = [Problem(source, field, message) for field, message in
                    [*clashes, *_unrepresentable(document, "")]]
        if not isinstance(self.name, str):
            problems.append(Problem(source, "name", f"expected a string, got "
                                                    f"{type(self.name).__name__}"))
        if problems:
            raise ScenarioError(problems)
        return _plain(document)

    def _merged(self) -> tuple[dict, list[tuple[str, str]]]:
        """The fields with the entries the calls added, and (field, problem) for each section
        given both ways or output name given twice or not as a string."""
        document, clashes = dict(self._document), []
        for section, entries in self._added.items():
            if not entries:
                continue
            if section in document:
                clashes.append((section, f"given both as a field of MechanismBuilder() and by "
                                         f"calls adding {section}; give it one way"))
                continue
            if section != "outputs":
                document[section] = entries
                continue
            document[section] = {}
            for name, table in entries:
                if not isinstance(name, str):
                    clashes.append((section, f"an output named by a {type(name).__name__}; "
                                             f"output names are strings"))
                elif name in document[section]:
                    clashes.append((_join(section, _key_text(name)), "output added twice"))
                else:
                    document[section][name] = table
        return document, clashes

    def build(self) -> Mechanism:
        """The validated mechanism.

        Raises
        ------
        ScenarioError
            With every problem found, each naming ``<python: NAME>`` and the field.
        """
        return from_document(self.document(), self.name, self.source)
