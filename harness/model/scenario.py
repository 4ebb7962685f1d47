"""Loading and validating scenario files (TOML, one mechanism per file in ``scenarios/``).

The validator walks the whole file, collects every problem with its field path and raises one
:class:`ScenarioError` listing them all (the sympy.physics.mechanics style), so a user fixes a file
in one pass.  Nothing here raises anything else for bad input.

This module finds a scenario (a shipped name, a path, or a member ``family@parameter`` of a
generated family: :mod:`mbh._harness.model.families`), reads the top-level fields and builds the
:class:`~mbh._harness.model.mechanism.Mechanism`.  The fields are read by the typed readers of
:mod:`mbh._harness.model.toml_fields`; each section by its own module, sharing a
:class:`~mbh._harness.model.scenario_reader.ScenarioReader`: ``[[bodies]]``
(:mod:`~mbh._harness.model.scenario_bodies`), ``[[joints]]``
(:mod:`~mbh._harness.model.scenario_joints`), ``[[forces]]``
(:mod:`~mbh._harness.model.scenario_forces`), ``[initial]``
(:mod:`~mbh._harness.model.scenario_initial`), ``[outputs]`` and ``[reference]``
(:mod:`~mbh._harness.model.scenario_outputs`).

The file format (sections, fields, units, defaults, limits, an example) is documented in
``docs/formats/scenario.md``.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from mbh._harness.common.errors import MbhError
from mbh._harness.common.kept_files import read_kept
from mbh._harness.common.locations import shipped
from mbh._harness.model.families import FamilyError, family_document, family_names
from mbh._harness.model.mechanism import Mechanism
from mbh._harness.model.scenario_bodies import check_held_turns, read_bodies
from mbh._harness.model.scenario_forces import read_forces
from mbh._harness.model.scenario_initial import read_initial
from mbh._harness.model.scenario_joints import read_joints
from mbh._harness.model.scenario_outputs import read_outputs, read_reference
from mbh._harness.model.scenario_reader import ScenarioReader
from mbh._harness.model.timegrid import EVALUATION_STEP, GRID_STEP, STEP_MATCH
from mbh._harness.model.toml_fields import Problem, _Collector, read_toml

__all__ = ["SCENARIO_DIR", "ScenarioError", "scenario_path", "scenario_names",
           "is_scenario_name", "load", "from_document"]

#: The shipped scenario files (mbh._harness.common.locations: the checkout's or the installed
#: package's).
SCENARIO_DIR = shipped("scenarios")

_TOP_KEYS = {"name", "kind", "plane", "duration", "sample_step", "gravity", "tags", "notes",
             "bodies", "joints", "forces", "initial", "outputs", "reference"}


class ScenarioError(MbhError, ValueError):
    """Raised once per file with every :class:`~mbh._harness.model.toml_fields.Problem` found."""

    def __init__(self, problems: list[Problem]):
        self.problems = problems
        super().__init__("\n".join(str(p) for p in problems))


def _hash(document: dict) -> str:
    """The content hash of ``document``: SHA-256 of its canonical JSON."""
    canonical = json.dumps(document, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(canonical.encode()).hexdigest()


def scenario_path(name: str) -> Path:
    """Path of the shipped scenario ``name`` (a file name without ``.toml``)."""
    return SCENARIO_DIR / f"{name}.toml"


def scenario_names() -> list[str]:
    """Names of the shipped scenarios, sorted."""
    return sorted(p.stem for p in SCENARIO_DIR.glob("*.toml"))


def is_scenario_name(name: str) -> bool:
    """Whether ``name`` names a shipped scenario or a member (``family@parameter``) of a known
    generated family; the member's parameter is checked when it loads."""
    family, at, _ = name.partition("@")
    if not at:
        return name in scenario_names()
    return family in family_names()


def load(name_or_path: str | Path) -> Mechanism:
    """Load and validate a scenario by shipped name or by path.

    Raises
    ------
    ScenarioError
        With every problem found, each naming the file and the field.
    """
    path = Path(name_or_path)
    if path.suffix != ".toml" and "@" in str(name_or_path):
        return _load_family_member(str(name_or_path))
    if path.suffix != ".toml":
        path = scenario_path(str(name_or_path))
    return read_kept("scenario", (path,), lambda: _load_file(path))


def _load_file(path: Path) -> Mechanism:
    """Read, validate and build the scenario file ``path`` (see :func:`load`)."""
    file = str(path)
    try:
        _, document = read_toml(path)
    except FileNotFoundError:
        known = ", ".join(scenario_names())
        missing = Problem(file, "-", f"no such scenario file (shipped: {known})")
        raise ScenarioError([missing]) from None
    except ValueError as error:
        raise ScenarioError([Problem(file, "-", str(error))]) from None
    return from_document(document, path.stem, file)


def from_document(document: dict, name: str, source: str) -> Mechanism:
    """Validate a scenario document (the dict a scenario file parses to) named ``name`` (the
    file's stem: its ``name`` key, if any, wins) and build its :class:`Mechanism`; ``source``
    names it in every problem, as a file path does.  Used by the file loader and the Python
    builder (:mod:`mbh._harness.model.builder`), so both check the same rules and hash the same
    document the same way.

    Raises
    ------
    ScenarioError
        With every problem found, each naming ``source`` and the field.
    """
    if not isinstance(document, dict):
        raise ScenarioError([Problem(source, "-", f"expected a table of fields, got "
                                                  f"{type(document).__name__}")])
    return _build(source, name, document)


def _load_family_member(name: str) -> Mechanism:
    """Member ``family@parameter`` of a generated family (:mod:`mbh._harness.model.families`),
    validated by the same loader as a file."""
    family, _, parameter = name.partition("@")
    file = f"harness/model/families.py: {name}"
    try:
        document = family_document(family, parameter)
    except FamilyError as error:
        raise ScenarioError([Problem(file, "-", str(error))]) from None
    except ValueError:  # int() refuses a parameter of over 4300 digits
        too_long = Problem(file, "-", f"family {family!r}: parameter of {len(parameter)} digits "
                                      "is out of range")
        raise ScenarioError([too_long]) from None
    return _build(file, name, document)


def _build(file: str, stem: str, document: dict) -> Mechanism:
    """Read every field of ``document`` (see :func:`from_document`) and build its Mechanism.

    Raises
    ------
    ScenarioError
        With every problem found, each naming ``file`` and the field.
    """
    c = _Collector(file)
    c.unknown_keys(document, _TOP_KEYS, "")
    name = c.name(document, "name", "", default=stem)
    kind = c.string(document, "kind", "")
    if kind is not None and kind not in ("planar", "spatial"):
        c.add("kind", f"expected 'planar' or 'spatial', got {kind!r}")
        kind = None
    if kind == "planar":
        plane = c.string(document, "plane", "")
        if plane is not None and plane != "xy":
            c.add("plane", f"only the 'xy' plane is supported, got {plane!r}")
    elif "plane" in document:
        c.add("plane", "only planar scenarios declare a plane")
    duration = c.number(document, "duration", "", positive=True)
    sample_step = _sample_step(c, document, duration)
    gravity = c.vector(document, "gravity", "")
    tags = document.get("tags", [])
    if not isinstance(tags, list) or not all(isinstance(t, str) for t in tags):
        c.add("tags", f"expected a list of strings, got {tags!r}")
        tags = []
    notes = document.get("notes", "")
    if not isinstance(notes, str):
        c.add("notes", "expected a string")
        notes = ""

    reader = ScenarioReader(c, document, planar=kind == "planar")
    inertia_fields = read_bodies(reader)
    read_joints(reader)
    check_held_turns(reader, inertia_fields)
    forces = read_forces(reader)
    initial = read_initial(reader)
    outputs = read_outputs(reader)
    branch, neutral_routes = read_reference(reader)
    if c.problems:
        raise ScenarioError(c.problems)
    return Mechanism(
        name=name, kind=kind, bodies=tuple(reader.bodies.values()),
        joints=tuple(reader.joints.values()), forces=tuple(forces), gravity=gravity,
        initial=initial, duration=duration, sample_step=sample_step, outputs=tuple(outputs),
        tags=tuple(tags),
        notes=notes, source=c.file, content_hash=_hash(document), branch=branch,
        neutral_routes=neutral_routes or bool(branch),
    )


def _sample_step(c: _Collector, document: dict, duration: float | None) -> float | None:
    """``sample_step`` (s): a multiple of the reference grid step, at most the duration."""
    step = c.number(document, "sample_step", "", default=EVALUATION_STEP, positive=True)
    if step is None:
        return None
    count = round(step / GRID_STEP)
    if count < 1 or abs(step - count * GRID_STEP) > STEP_MATCH * step:
        c.add("sample_step", f"{step!r} s is not a multiple of the reference grid step "
              f"{GRID_STEP:g} s")
        return None
    if duration is not None and step > duration:
        c.add("sample_step", f"{step!r} s is longer than the duration {duration!r} s")
        return None
    return count * GRID_STEP
