"""Loading and validating scenario files (TOML, one mechanism per file in ``scenarios/``).

The validator walks the whole file, collects every problem with its field path and raises one
:class:`ScenarioError` listing them all (the sympy.physics.mechanics style), so a user fixes a file
in one pass.  Nothing here raises anything else for bad input.

The file format (sections, fields, units, defaults, limits, an example) is documented in
``docs/formats/scenario.md``.
"""

from __future__ import annotations

import hashlib
import json
import math
import sys
import tomllib
import unicodedata
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
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
    Output,
    Prescribed,
    PrescribedJointRate,
    PrescribedPointVelocity,
    SpringDamper,
)
from mbh._harness.model.families import FamilyError, family_document, family_names
from mbh._harness.model import parts as shapes
from mbh._harness.model.free_turns import ZERO_MOMENT as _ZERO_MOMENT, free_turn
from mbh._harness.model.timegrid import EVALUATION_STEP, GRID_STEP, STEP_MATCH
from mbh._harness.common.errors import MbhError
from mbh._harness.common.kept_files import read_kept
from mbh._harness.common.locations import shipped

#: The shipped scenario files (mbh._harness.common.locations: the checkout's or the installed package's).
SCENARIO_DIR = shipped("scenarios")

_TOP_KEYS = {"name", "kind", "plane", "duration", "sample_step", "gravity", "tags", "notes", "bodies", "joints",
             "forces", "initial", "outputs", "reference"}
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
_JOINT_KEYS = {"name", "type", "body1", "body2", "location", "location2", "axis", "axis2", "normal"}
_FORCE_KEYS = {
    "joint_torque": {"type", "joint", "value"},
    "joint_force": {"type", "joint", "value"},
    "body_force": {"type", "body", "force", "point"},
    "body_torque": {"type", "body", "torque"},
    "spring_damper": {"type", "name", "body1", "body2", "location1", "location2", "stiffness",
                      "damping", "free_length"},
}
_OUTPUT_KINDS = {"joint_angle": "joint", "joint_rate": "joint", "joint_position": "joint",
                 "position": "body", "velocity": "body",
                 "point_position": "point", "point_velocity": "point"}
_OUTPUT_KEYS = {"joint": {"kind", "joint", "offset"}, "body": {"kind", "body", "component"},
                "point": {"kind", "body", "location", "component"}}
_INITIAL_KEYS = {"driver", "value", "rate", "guess", "velocities"}
_JOINT_RATE_KEYS = {"joint", "rate"}
_POINT_VELOCITY_KEYS = {"body", "location", "velocity", "components"}
_COMPONENTS = {"x": 0, "y": 1, "z": 2}
_AXIS_TOL = 1e-9
#: Largest magnitude of any number in a file, and smallest mass or duration: the engines multiply
#: up to three such numbers (m·v², I·ω², r × F), and 1e100³ stays below the double range (1.8e308).
_LARGEST = 1e100
_SMALLEST = 1e-100
#: Unicode categories a name may not contain: control, format (e.g. right-to-left override,
#: zero-width space), surrogate, private-use, unassigned, line and paragraph separators.
_UNPRINTABLE = {"Cc", "Cf", "Cs", "Co", "Cn", "Zl", "Zp"}


@dataclass(frozen=True)
class Problem:
    """One validation finding: ``file: field: message``."""

    file: str
    field: str
    message: str

    def __str__(self) -> str:
        return f"{self.file}: {self.field}: {self.message}"


class ScenarioError(MbhError, ValueError):
    """Raised once per file with every :class:`Problem` found."""

    def __init__(self, problems: list[Problem]):
        self.problems = problems
        super().__init__("\n".join(str(p) for p in problems))


#: What :meth:`_Collector._given` returns for a required field that is missing.
_MISSING = object()


class _Collector:
    """Typed field readers that record a problem instead of raising."""

    def __init__(self, file: str):
        self.file = file
        self.problems: list[Problem] = []

    def add(self, field: str, message: str) -> None:
        self.problems.append(Problem(self.file, field, message))

    def unknown_keys(self, table: dict, allowed: set[str], path: str) -> None:
        for key in sorted(set(table) - allowed):
            self.add(_join(path, _key_text(key)),
                     f"unknown key (allowed: {', '.join(sorted(allowed))})")

    def required(self, table: dict, key: str, path: str) -> Any:
        if key not in table:
            self.add(_join(path, key), "missing required field")
            return None
        return table[key]

    def _given(self, table: dict, key: str, path: str, default: Any) -> Any:
        """``table[key]`` if present (a None from a Python caller included: the typed readers
        name it), else ``default`` if not None, else :data:`_MISSING` with the problem added."""
        if key in table:
            return table[key]
        if default is not None:
            return default
        self.add(_join(path, key), "missing required field")
        return _MISSING

    def string(self, table: dict, key: str, path: str, default: str | None = None) -> str | None:
        value = self._given(table, key, path, default)
        if value is _MISSING:
            return None
        if not isinstance(value, str) or not value:
            self.add(_join(path, key), f"expected a non-empty string, got {value!r}")
            return None
        return value

    def name(self, table: dict, key: str, path: str, default: str | None = None) -> str | None:
        """A non-empty string fit to name something (see :func:`name_problem`)."""
        value = self.string(table, key, path, default)
        problem = None if value is None else name_problem(value)
        if problem:
            self.add(_join(path, key), problem)
            return None
        return value

    def number(self, table: dict, key: str, path: str, default: float | None = None,
               positive: bool = False, nonnegative: bool = False) -> float | None:
        value = self._given(table, key, path, default)
        if value is _MISSING:
            return None
        if not finite_number(value):
            self.add(_join(path, key), f"expected a finite number, got {value!r}")
            return None
        if abs(value) > _LARGEST:
            self.add(_join(path, key), f"magnitude {value:g} exceeds the limit {_LARGEST:g}")
            return None
        if positive and value <= 0:
            self.add(_join(path, key), f"must be > 0, got {value!r}")
            return None
        if positive and value < _SMALLEST:
            self.add(_join(path, key), f"{value:g} is below the smallest allowed {_SMALLEST:g}")
            return None
        if nonnegative and value < 0:
            self.add(_join(path, key), f"must be >= 0, got {value!r}")
            return None
        return float(value)

    def vector(self, table: dict, key: str, path: str, length: tuple[int, ...] = (3,),
               required: bool = True, nonzero: bool = False) -> np.ndarray | None:
        if key not in table:
            if required:
                self.add(_join(path, key), "missing required field")
            return None
        value = table[key]
        field = _join(path, key)
        if (not isinstance(value, list) or len(value) not in length
                or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)):
            sizes = " or ".join(str(n) for n in length)
            self.add(field, f"expected a list of {sizes} numbers, got {value!r}")
            return None
        if not all(finite_number(v) for v in value):
            self.add(field, f"contains a non-finite value: {value!r}")
            return None
        array = np.asarray(value, dtype=float)
        if not np.all(np.isfinite(array)):
            self.add(field, f"contains a non-finite value: {value!r}")
            return None
        if np.abs(array).max() > _LARGEST:
            self.add(field, f"a magnitude exceeds the limit {_LARGEST:g}: {value!r}")
            return None
        if nonzero and np.linalg.norm(array) < _AXIS_TOL:
            self.add(field, "zero-length vector")
            return None
        return array


def finite_number(value: Any) -> bool:
    """Whether ``value`` is a number (not a bool) that is finite as a double: TOML reads integers
    of any size, and one beyond the double range (±1.8e308) cannot become a float."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return False
    return abs(value) <= sys.float_info.max if isinstance(value, int) else math.isfinite(value)


def read_toml(path: Path) -> tuple[str, dict]:
    """The text of ``path`` and the TOML document it holds.

    Raises
    ------
    FileNotFoundError
        When there is no such file.
    ValueError
        When the file cannot be read or is not TOML; the message says why (``cannot read the
        file: ...`` or ``not valid TOML: ...``; tomllib raises ValueError for an integer of over
        4300 digits and RecursionError for arrays nested a few hundred deep).
    """
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise
    except UnicodeDecodeError as error:
        raise ValueError(f"not valid TOML: {error}") from None
    except (OSError, ValueError) as error:  # a folder, no permission, a NUL in the name
        raise ValueError(f"cannot read the file: {error}") from None
    try:
        return text, tomllib.loads(text)
    except ValueError as error:  # TOMLDecodeError, or an integer too long to convert
        raise ValueError(f"not valid TOML: {error}") from None
    except RecursionError:
        raise ValueError("not valid TOML: arrays or tables nested too deeply to read") from None


def name_problem(name: str) -> str | None:
    """Why ``name`` cannot name a scenario, body, joint, force or output, or None.

    Names are printed in tables and messages, so they must be printable and not padded; markup,
    emoji and other printable characters are fine (every output escapes them).
    """
    bad = next((ch for ch in name if unicodedata.category(ch) in _UNPRINTABLE), None)
    if bad is not None:
        return (f"name {name!r} contains the unprintable character U+{ord(bad):04X} "
                f"({unicodedata.category(bad)}); names must be printable")
    if name != name.strip():
        return f"name {name!r} has leading or trailing whitespace"
    return None


def _missing(*values) -> bool:
    """True if any value is None (arrays compare element-wise, so ``None in`` cannot be used)."""
    return any(v is None for v in values)


def _join(path: str, key: str) -> str:
    return f"{path}.{key}" if path else key


def _key_text(key: str) -> str:
    """``key`` as TOML writes it: bare when it can be, else quoted, so that an empty, spaced or
    unprintable key still shows in the problem's field (``""``, not an empty field)."""
    bare = key.isascii() and key.replace("_", "").replace("-", "").isalnum()
    return key if bare else json.dumps(key)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _perpendicular(axis: np.ndarray) -> np.ndarray:
    """A unit vector perpendicular to ``axis`` (deterministic choice)."""
    trial = np.eye(3)[int(np.argmin(np.abs(axis)))]
    return _unit(trial - axis * (trial @ axis))


def inertia_tensor(values: np.ndarray) -> np.ndarray:
    """Inertia tensor from ``[Ixx, Iyy, Izz]`` or ``[Ixx, Iyy, Izz, Ixy, Ixz, Iyz]`` (kg·m²)."""
    if len(values) == 3:
        return np.diag(values)
    ixx, iyy, izz, ixy, ixz, iyz = values
    return np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])


def inertia_problem(tensor: np.ndarray) -> str | None:
    """Why ``tensor`` is not a physical inertia tensor, or None.

    Accepts a positive definite tensor obeying the triangle inequality, a slender bar's: one
    principal moment zero (below ``_ZERO_MOMENT`` of the trace), the other two equal (the triangle
    inequality with equality), or a point mass's: all three zero.  Whether the joints hold the
    turns such a body has no inertia against is checked with the joints
    (:mod:`mbh._harness.model.free_turns`).
    """
    principal = np.linalg.eigvalsh(tensor)
    total = principal.sum()
    zero = _ZERO_MOMENT * abs(total)
    listed = f"(principal moments {principal.tolist()})"
    if principal[0] < -zero:
        return f"has a negative principal moment {listed}"
    if principal[2] <= zero:
        return None  # a point mass
    if principal[1] <= zero:
        return (f"has two zero principal moments {listed}; only a slender bar (one zero moment, "
                "about its axis) or a point mass (all three zero) may have any")
    for moment in principal:
        if moment > total - moment + _ZERO_MOMENT * total:
            return ("breaks the triangle inequality: principal moment "
                    f"{moment:g} exceeds the sum of the other two ({total - moment:g})")
    return None


def _hash(document: dict) -> str:
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
        raise ScenarioError([Problem(file, "-", f"no such scenario file (shipped: {known})")]) from None
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
    return _Builder(source, name, document).build()


def _load_family_member(name: str) -> Mechanism:
    """Member ``family@parameter`` of a generated family (:mod:`mbh._harness.model.families`), validated by
    the same loader as a file."""

    family, _, parameter = name.partition("@")
    file = f"harness/model/families.py: {name}"
    try:
        document = family_document(family, parameter)
    except FamilyError as error:
        raise ScenarioError([Problem(file, "-", str(error))]) from None
    except ValueError:  # int() refuses a parameter of over 4300 digits
        raise ScenarioError([Problem(file, "-", f"family {family!r}: parameter of "
                                                f"{len(parameter)} digits is out of range")]) from None
    return _Builder(file, name, document).build()


class _Builder:
    """Turns a parsed TOML document into a :class:`Mechanism`, collecting problems."""

    def __init__(self, file: str, stem: str, document: dict):
        self.c = _Collector(file)
        self.stem = stem
        self.doc = document
        self.bodies: dict[str, Body] = {}
        self.joints: dict[str, Joint] = {}

    def build(self) -> Mechanism:
        c, doc = self.c, self.doc
        c.unknown_keys(doc, _TOP_KEYS, "")
        name = c.name(doc, "name", "", default=self.stem)
        kind = c.string(doc, "kind", "")
        if kind is not None and kind not in ("planar", "spatial"):
            c.add("kind", f"expected 'planar' or 'spatial', got {kind!r}")
            kind = None
        if kind == "planar":
            plane = c.string(doc, "plane", "")
            if plane is not None and plane != "xy":
                c.add("plane", f"only the 'xy' plane is supported, got {plane!r}")
        elif "plane" in doc:
            c.add("plane", "only planar scenarios declare a plane")
        self.planar = kind == "planar"
        duration = c.number(doc, "duration", "", positive=True)
        sample_step = self._sample_step(duration)
        gravity = c.vector(doc, "gravity", "")
        tags = doc.get("tags", [])
        if not isinstance(tags, list) or not all(isinstance(t, str) for t in tags):
            c.add("tags", f"expected a list of strings, got {tags!r}")
            tags = []
        notes = doc.get("notes", "")
        if not isinstance(notes, str):
            c.add("notes", "expected a string")
            notes = ""

        self._bodies()
        self._joints()
        self._held_turns()
        forces = self._forces()
        initial = self._initial()
        outputs = self._outputs()
        branch, neutral_routes = self._reference()
        if c.problems:
            raise ScenarioError(c.problems)
        return Mechanism(
            name=name, kind=kind, bodies=tuple(self.bodies.values()),
            joints=tuple(self.joints.values()), forces=tuple(forces), gravity=gravity,
            initial=initial, duration=duration, sample_step=sample_step, outputs=tuple(outputs),
            tags=tuple(tags),
            notes=notes, source=c.file, content_hash=_hash(doc), branch=branch,
            neutral_routes=neutral_routes or bool(branch),
        )

    def _sample_step(self, duration: float | None) -> float | None:
        """``sample_step`` (s): a multiple of the reference grid step, at most the duration."""
        step = self.c.number(self.doc, "sample_step", "", default=EVALUATION_STEP, positive=True)
        if step is None:
            return None
        count = round(step / GRID_STEP)
        if count < 1 or abs(step - count * GRID_STEP) > STEP_MATCH * step:
            self.c.add("sample_step", f"{step!r} s is not a multiple of the reference grid step "
                       f"{GRID_STEP:g} s")
            return None
        if duration is not None and step > duration:
            self.c.add("sample_step", f"{step!r} s is longer than the duration {duration!r} s")
            return None
        return count * GRID_STEP

    # -- sections -------------------------------------------------------------------------
    def _tables(self, key: str, required: bool) -> list[tuple[str, dict]]:
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

    def _unique_name(self, table: dict, path: str, seen: dict, reserved=()) -> str | None:
        name = self.c.name(table, "name", path)
        if name is None:
            return None
        if name in seen or name in reserved:
            self.c.add(_join(path, "name"), f"duplicate name {name!r}")
            return None
        return name

    def _bodies(self) -> None:
        c = self.c
        self.inertia_fields: dict[str, str] = {}
        for path, table in self._tables("bodies", required=True):
            c.unknown_keys(table, _BODY_KEYS, path)
            name = self._unique_name(table, path, self.bodies, reserved=(GROUND,))
            rotation = self._orientation(table, path)
            if "parts" in table:
                mass, inertia, position = self._body_of_parts(table, path, rotation)
            else:
                mass, inertia, position = self._body_given(table, path)
            if not _missing(name, mass, inertia, position, rotation):
                self.bodies[name] = Body(name, mass, inertia, position, rotation)
                self.inertia_fields[name] = _join(path, "parts" if "parts" in table else "inertia")
            elif name is not None:
                self.bodies[name] = None  # known name, invalid body: keeps references quiet

    def _body_given(self, table: dict, path: str) -> tuple:
        """(mass kg, centroidal inertia (3, 3) in the body frame, centre of mass (3,) m) as
        written, each None where invalid."""
        c = self.c
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
        if self.planar and position is not None and position[2] != 0.0:
            c.add(_join(path, "position"), "a planar body must lie in z = 0")
        return mass, inertia, position

    def _body_of_parts(self, table: dict, path: str, rotation: np.ndarray | None) -> tuple:
        """(mass kg, centroidal inertia (3, 3) in the body frame of ``rotation``, centre of
        mass (3,) m) of the body's ``parts`` (:mod:`mbh._harness.model.parts`), or Nones."""
        c = self.c
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
        found = [self._part(entry, f"{field}[{index}]") for index, entry in enumerate(entries)]
        if _missing(*found):
            return None, None, None
        whole = shapes.combined(found)
        if not (np.all(np.isfinite(whole.inertia)) and np.abs(whole.inertia).max() <= _LARGEST
                and whole.mass <= _LARGEST):
            c.add(field, f"the parts' mass or inertia exceeds the limit {_LARGEST:g}")
            return None, None, None
        inertia = None if rotation is None else rotation.T @ whole.inertia @ rotation
        return whole.mass, inertia, whole.centre

    def _part(self, table: dict, path: str) -> shapes.MassProperties | None:
        """One part: its type, placement and size, and its mass or density."""
        c = self.c
        kind = c.string(table, "type", path)
        if kind is None:
            return None
        if kind not in _PART_KEYS:
            c.add(_join(path, "type"), f"unknown part type {kind!r} "
                  f"(known: {', '.join(_PART_KEYS)})")
            return None
        c.unknown_keys(table, _PART_KEYS[kind], path)
        centre = self._planar_point(table, "position", path)
        shape = getattr(self, f"_part_{kind}")(table, path)  # (measure, mass → part) or None
        mass = self._part_mass(table, path, kind, None if shape is None else shape[0])
        if _missing(centre, shape, mass):
            return None
        return shape[1](mass, centre)

    def _part_mass(self, table: dict, path: str, kind: str, measure: float | None) -> float | None:
        """The part's ``mass`` (kg), or ``density`` times its ``measure`` (length m or volume
        m³); a point takes mass only."""
        c = self.c
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
        if not _SMALLEST <= mass <= _LARGEST:
            c.add(_join(path, "density"), f"gives a mass of {mass:g} kg, outside "
                  f"[{_SMALLEST:g}, {_LARGEST:g}]")
            return None
        return mass

    # Each _part_<type> reads the type's size keys and returns (measure: length m or volume m³,
    # a function of (mass kg, centre (3,) m) giving the part), or None with the problems added.
    def _part_point(self, table, path):
        return 0.0, shapes.point

    def _part_rod(self, table, path):
        length = self.c.number(table, "length", path, positive=True)
        axis = self.c.vector(table, "axis", path, nonzero=True)
        if _missing(length, axis):
            return None
        return length, lambda mass, centre: shapes.rod(mass, length, centre, axis)

    def _part_box(self, table, path):
        size = self.c.vector(table, "size", path)
        if size is not None and not np.all(size > 0.0):
            self.c.add(_join(path, "size"), f"edge lengths must be > 0, got {size.tolist()}")
            size = None
        rotation = self._orientation(table, path, "box")
        if _missing(size, rotation):
            return None
        return (shapes.box_volume(size),
                lambda mass, centre: shapes.box(mass, size, centre, rotation))

    def _part_cylinder(self, table, path):
        radius = self.c.number(table, "radius", path, positive=True)
        length = self.c.number(table, "length", path, positive=True)
        axis = self.c.vector(table, "axis", path, nonzero=True)
        if _missing(radius, length, axis):
            return None
        return (shapes.cylinder_volume(radius, length),
                lambda mass, centre: shapes.cylinder(mass, radius, length, centre, axis))

    def _part_sphere(self, table, path):
        radius = self.c.number(table, "radius", path, positive=True)
        if radius is None:
            return None
        return (shapes.sphere_volume(radius),
                lambda mass, centre: shapes.sphere(mass, radius, centre))

    def _held_turns(self) -> None:
        """Every body with zero principal moments must have the turns about those axes held by
        its joints (:mod:`mbh._harness.model.free_turns`).  Skipped while a joint has problems: a
        free turn would then only echo them."""
        joints = [joint for joint in self.joints.values() if joint is not None]
        tables = self.doc.get("joints")
        if not isinstance(tables, list) or len(joints) != len(tables):
            return
        for name, body in self.bodies.items():
            turn = None if body is None else free_turn(body, joints, self.planar)
            if turn is not None:
                self.c.add(self.inertia_fields[name], (
                    f"body {name!r} has no inertia about the axis {np.round(turn, 12).tolist()} "
                    f"through its centre of mass {body.position.tolist()} and its joints leave "
                    "that turn free, so its motion is undetermined; tie it by a joint at a point "
                    "away from the centre of mass (a revolute whose axis misses it; a spherical "
                    "joint leaves the turn about the line to the joint free)"))

    def _orientation(self, table: dict, path: str, what: str = "body") -> np.ndarray | None:
        """The rotation (3, 3) a body or box is given by (``what`` names it in problems)."""
        c = self.c
        given = [k for k in ("angle_deg", "euler313_deg", "quaternion") if k in table]
        if len(given) > 1:
            c.add(path, f"give one orientation, not {', '.join(given)}")
            return None
        if self.planar:
            if given and given[0] != "angle_deg":
                c.add(_join(path, given[0]), f"a planar {what} takes angle_deg")
                return None
            angle = c.number(table, "angle_deg", path, default=0.0)
            return None if angle is None else Rotation.from_euler("z", angle, degrees=True).as_matrix()
        if not given:
            return np.eye(3)
        if given[0] == "euler313_deg":
            angles = c.vector(table, "euler313_deg", path)
            return None if angles is None else Rotation.from_euler("ZXZ", angles, degrees=True).as_matrix()
        if given[0] == "quaternion":
            quat = c.vector(table, "quaternion", path, length=(4,), nonzero=True)
            return None if quat is None else Rotation.from_quat(quat, scalar_first=True).as_matrix()
        c.add(_join(path, "angle_deg"), f"a spatial {what} takes euler313_deg or quaternion")
        return None

    def _body_ref(self, table: dict, key: str, path: str) -> str | None:
        name = self.c.string(table, key, path)
        if name is None or name == GROUND:
            return name
        if name not in self.bodies:
            known = ", ".join([GROUND, *self.bodies])
            self.c.add(_join(path, key), f"unknown body {name!r} (known: {known})")
            return None
        return name

    def _local_point(self, body: str, world: np.ndarray) -> np.ndarray:
        if body == GROUND:
            return world.copy()
        b = self.bodies[body]
        return b.rotation.T @ (world - b.position)

    def _local_direction(self, body: str, world: np.ndarray) -> np.ndarray:
        return world.copy() if body == GROUND else self.bodies[body].rotation.T @ world

    def _joints(self) -> None:
        c = self.c
        for path, table in self._tables("joints", required=True):
            c.unknown_keys(table, _JOINT_KEYS, path)
            name = self._unique_name(table, path, self.joints)
            jtype = c.string(table, "type", path)
            allowed = PLANAR_JOINT_TYPES if self.planar else JOINT_TYPES
            if jtype is not None and jtype not in allowed:
                kind = "planar" if self.planar else "spatial"
                c.add(_join(path, "type"), f"unknown {kind} joint type {jtype!r} "
                      f"(known: {', '.join(allowed)})")
                jtype = None
            body1 = self._body_ref(table, "body1", path)
            body2 = self._body_ref(table, "body2", path)
            if body1 is not None and body1 == body2:
                c.add(_join(path, "body2"), f"a joint needs two different bodies, got {body1!r} twice")
                body2 = None
            location = c.vector(table, "location", path)
            location2 = c.vector(table, "location2", path, required=False)
            needs_axis = jtype not in (None, "spherical") and not (self.planar and jtype == "revolute")
            axis = c.vector(table, "axis", path, required=needs_axis, nonzero=True)
            axis2 = c.vector(table, "axis2", path, required=jtype == "universal", nonzero=True)
            normal = c.vector(table, "normal", path, required=False, nonzero=True)
            if self.planar:
                axis = self._planar_axis(jtype, axis, path)
                for key, point in (("location", location), ("location2", location2)):
                    if point is not None and point[2] != 0.0:
                        c.add(_join(path, key), "a planar joint must lie in z = 0")
            if jtype == "spherical" and axis is None:
                axis = np.array([0.0, 0.0, 1.0])
            if jtype == "universal" and axis is not None and axis2 is not None:
                if abs(_unit(axis) @ _unit(axis2)) > 1e-9:
                    c.add(_join(path, "axis2"), "the universal joint's cross axes must be perpendicular")
                    axis2 = None
            if normal is not None and axis is not None and abs(_unit(normal) @ _unit(axis)) > 1e-9:
                c.add(_join(path, "normal"), "must be perpendicular to the axis")
                normal = None
            parts = (name, jtype, body1, body2, location, axis)
            if _missing(*parts) or (jtype == "universal" and axis2 is None) \
                    or self.bodies.get(body1, 0) is None or self.bodies.get(body2, 0) is None:
                if name is not None:
                    self.joints[name] = None
                continue
            self.joints[name] = self._joint(name, jtype, body1, body2, location, location2,
                                            _unit(axis), None if axis2 is None else _unit(axis2),
                                            None if normal is None else _unit(normal))

    def _planar_axis(self, jtype, axis, path) -> np.ndarray | None:
        z = np.array([0.0, 0.0, 1.0])
        if jtype == "revolute":
            if axis is not None and np.linalg.norm(np.cross(_unit(axis), z)) > 1e-9:
                self.c.add(_join(path, "axis"), "a planar revolute joint turns about z")
                return None
            return z if axis is None else _unit(axis)
        if axis is not None and abs(axis[2]) > 0:
            self.c.add(_join(path, "axis"), "a planar prismatic axis must lie in the x–y plane")
            return None
        return axis

    def _joint(self, name, jtype, body1, body2, location, location2, axis, axis2, normal) -> Joint:
        point1 = self._local_point(body1, location)
        point2 = self._local_point(body2, location if location2 is None else location2)
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
            axis1=self._local_direction(body1, axis), axis2=self._local_direction(body2, second),
            normal1=self._local_direction(body1, normal), normal2=self._local_direction(body2, normal),
        )

    def _forces(self) -> list:
        c = self.c
        forces = []
        for path, table in self._tables("forces", required=False):
            ftype = c.string(table, "type", path)
            if ftype is None:
                continue
            if ftype not in _FORCE_KEYS:
                c.add(_join(path, "type"), f"unknown force type {ftype!r} "
                      f"(known: {', '.join(sorted(_FORCE_KEYS))})")
                continue
            c.unknown_keys(table, _FORCE_KEYS[ftype], path)
            force = getattr(self, f"_force_{ftype}")(table, path)
            if force is not None:
                forces.append(force)
        return forces

    def _offset(self, spec: dict, kind: str, path: str) -> float | None:
        """A joint output's ``offset`` (rad, default 0): only ``joint_angle`` takes one."""
        if "offset" in spec and kind != "joint_angle":
            self.c.add(_join(path, "offset"), f"only joint_angle outputs take an offset, not {kind}")
            return None
        return self.c.number(spec, "offset", path, default=0.0)

    def _joint_ref(self, table: dict, path: str, types=()) -> str | None:
        name = self.c.string(table, "joint", path)
        if name is None:
            return None
        return self._known_joint(name, _join(path, "joint"), types,
                                 f"; expected one of {', '.join(types)}")

    def _known_joint(self, name: str, field: str, types=(), rule: str = "") -> str | None:
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

    def _force_joint_torque(self, table, path):
        joint = self._joint_ref(table, path, types=("revolute", "cylindrical"))
        value = self.c.number(table, "value", path)
        return None if _missing(joint, value) else JointActuation(joint, value)

    def _force_joint_force(self, table, path):
        joint = self._joint_ref(table, path, types=("prismatic", "translational", "cylindrical"))
        value = self.c.number(table, "value", path)
        return None if _missing(joint, value) else JointActuation(joint, value)

    def _force_body_force(self, table, path):
        body = self._body_ref(table, "body", path)
        force = self.c.vector(table, "force", path)
        point = self.c.vector(table, "point", path, required=False)
        if _missing(body, force) or body == GROUND or self.bodies[body] is None:
            return None
        local = np.zeros(3) if point is None else self._local_point(body, point)
        return BodyForce(body, force, local)

    def _force_body_torque(self, table, path):
        body = self._body_ref(table, "body", path)
        torque = self.c.vector(table, "torque", path)
        return None if _missing(body, torque) or body == GROUND else BodyTorque(body, torque)

    def _force_spring_damper(self, table, path):
        c = self.c
        name = c.name(table, "name", path, default="spring")
        body1 = self._body_ref(table, "body1", path)
        body2 = self._body_ref(table, "body2", path)
        loc1 = c.vector(table, "location1", path)
        loc2 = c.vector(table, "location2", path)
        k = c.number(table, "stiffness", path, nonnegative=True)
        d = c.number(table, "damping", path, default=0.0, nonnegative=True)
        length = c.number(table, "free_length", path, nonnegative=True)
        if _missing(name, body1, body2, loc1, loc2, k, d, length) \
                or self.bodies.get(body1, 0) is None or self.bodies.get(body2, 0) is None:
            return None
        return SpringDamper(name, body1, body2, self._local_point(body1, loc1),
                            self._local_point(body2, loc2), k, d, length)

    def _initial(self) -> InitialState | None:
        c = self.c
        table = self.doc.get("initial")
        if not isinstance(table, dict):
            c.add("initial", "missing required section [initial] with the driver")
            return None
        c.unknown_keys(table, _INITIAL_KEYS, "initial")
        driver = self._drivable_joint(table, "driver", "initial")
        value = c.number(table, "value", "initial", default=0.0)
        rate = c.number(table, "rate", "initial", default=0.0)
        guess = {}
        raw_guess = table.get("guess", {})
        if not isinstance(raw_guess, dict):
            c.add("initial.guess", "expected a table of body = [x, y, z]")
            raw_guess = {}
        for body in raw_guess:
            if body not in self.bodies:
                c.add(f"initial.guess.{body}", f"unknown body {body!r}")
                continue
            point = c.vector(raw_guess, body, "initial.guess")
            if point is not None:
                guess[body] = point
        prescribed = self._prescribed(table, driver)
        if _missing(driver, value, rate, prescribed):
            return None
        return InitialState(driver, value, rate, guess, prescribed)

    def _reference(self) -> tuple[tuple[tuple[str, str], ...], bool]:
        """The ``[reference]`` table: pairs of revolute or cylindrical joints that turn by equal
        angles on the motion's assembly branch, and whether the reference takes the neutral
        routes (``routes = "neutral"``; the default ``"inhouse"``)."""
        c = self.c
        table = self.doc.get("reference", {})
        if not isinstance(table, dict):
            c.add("reference", "expected a table")
            return (), False
        c.unknown_keys(table, {"equal_joint_angles", "routes"}, "reference")
        routes = table.get("routes", "inhouse")
        if routes not in ("inhouse", "neutral"):
            c.add("reference.routes", f"expected 'inhouse' or 'neutral', got {routes!r}")
        pairs = table.get("equal_joint_angles", [])
        field = "reference.equal_joint_angles"
        if not isinstance(pairs, list):
            c.add(field, f"expected a list of joint-name pairs, got {pairs!r}")
            return (), False
        branch = []
        for index, pair in enumerate(pairs):
            path = f"{field}[{index}]"
            if not (isinstance(pair, list) and len(pair) == 2
                    and all(isinstance(n, str) for n in pair)):
                c.add(path, f"expected a pair of joint names, got {pair!r}")
                continue
            if pair[0] == pair[1]:
                c.add(path, f"a joint paired with itself ({pair[0]!r})")
                continue
            known = [self._known_joint(name, path, ("revolute", "cylindrical"),
                                       ", which has no angle") for name in pair]
            if all(known):
                branch.append((pair[0], pair[1]))
        return tuple(branch), routes == "neutral"

    def _drivable_joint(self, table: dict, key: str, path: str) -> str | None:
        """The joint named by ``table[key]`` if it exists and has a single coordinate."""
        name = self.c.string(table, key, path)
        if name is None:
            return None
        return self._known_joint(name, _join(path, key), DRIVABLE,
                                 ", which has no single coordinate; drivable types: "
                                 f"{', '.join(DRIVABLE)}")

    def _prescribed(self, table: dict, driver: str | None) -> tuple[Prescribed, ...] | None:
        """The ``[[initial.velocities]]`` entries, or None if any is invalid."""
        entries = table.get("velocities", [])
        if not isinstance(entries, list) or not all(isinstance(e, dict) for e in entries):
            self.c.add("initial.velocities", "expected an array of tables ([[initial.velocities]])")
            return None
        prescribed, valid, seen_joints = [], True, set()
        for index, entry in enumerate(entries):
            path = f"initial.velocities[{index}]"
            if ("joint" in entry) == ("body" in entry):
                self.c.add(path, "give either joint (with rate) or body (with location and "
                           "velocity)")
                valid = False
                continue
            if "joint" in entry:
                item = self._prescribed_rate(entry, path, driver, seen_joints)
            else:
                item = self._prescribed_point(entry, path)
            valid = valid and item is not None
            prescribed.append(item)
        return tuple(prescribed) if valid else None

    def _prescribed_rate(self, entry: dict, path: str, driver: str | None,
                         seen: set[str]) -> PrescribedJointRate | None:
        self.c.unknown_keys(entry, _JOINT_RATE_KEYS, path)
        joint = self._drivable_joint(entry, "joint", path)
        rate = self.c.number(entry, "rate", path)
        if joint is not None and joint == driver:
            self.c.add(_join(path, "joint"), f"joint {joint!r} is the driver; its rate is "
                       "initial.rate")
            return None
        if joint is not None and joint in seen:
            self.c.add(_join(path, "joint"), f"joint {joint!r} is prescribed twice")
            return None
        if joint is not None:
            seen.add(joint)
        return None if _missing(joint, rate) else PrescribedJointRate(joint, rate)

    def _prescribed_point(self, entry: dict, path: str) -> PrescribedPointVelocity | None:
        c = self.c
        c.unknown_keys(entry, _POINT_VELOCITY_KEYS, path)
        body = self._moving_body(entry, path)
        location = self._planar_point(entry, "location", path)
        velocity = self._planar_point(entry, "velocity", path)
        components = self._components(entry, path)
        if _missing(body, location, velocity, components):
            return None
        return PrescribedPointVelocity(body, self._local_point(body, location), velocity,
                                       components)

    def _moving_body(self, table: dict, path: str) -> str | None:
        """A known, valid, non-ground body named by ``table["body"]``."""
        body = self._body_ref(table, "body", path)
        if body == GROUND:
            self.c.add(_join(path, "body"), "ground does not move; name a body")
            return None
        if body is None or self.bodies[body] is None:
            return None
        return body

    def _planar_point(self, table: dict, key: str, path: str) -> np.ndarray | None:
        """A 3-vector; in a planar scene its z component must be 0."""
        point = self.c.vector(table, key, path)
        if self.planar and point is not None and point[2] != 0.0:
            self.c.add(_join(path, key), "a planar scene lies in z = 0")
            return None
        return point

    def _components(self, entry: dict, path: str) -> tuple[int, ...] | None:
        letters = ("x", "y") if self.planar else ("x", "y", "z")
        raw = entry.get("components", list(letters))
        field = _join(path, "components")
        if (not isinstance(raw, list) or not raw
                or not all(isinstance(letter, str) and letter in letters for letter in raw)
                or len(set(raw)) != len(raw)):
            self.c.add(field, f"expected a non-empty list of distinct components from "
                       f"{', '.join(letters)}, got {raw!r}")
            return None
        return tuple(_COMPONENTS[letter] for letter in raw)

    def _outputs(self) -> list[Output]:
        c = self.c
        table = self.doc.get("outputs", {})
        if not isinstance(table, dict):
            c.add("outputs", "expected a table of name = { kind = ..., ... }")
            return []
        outputs = []
        for name, spec in table.items():
            path = f"outputs.{name}"
            problem = name_problem(name)
            if problem:
                c.add(f"outputs[{name!r}]", problem)
                continue
            if not isinstance(spec, dict):
                c.add(path, "expected an inline table { kind = ..., ... }")
                continue
            kind = c.string(spec, "kind", path)
            if kind is None:
                continue
            if kind not in _OUTPUT_KINDS:
                c.add(_join(path, "kind"), f"unknown output kind {kind!r} "
                      f"(known: {', '.join(_OUTPUT_KINDS)})")
                continue
            ref = _OUTPUT_KINDS[kind]
            c.unknown_keys(spec, _OUTPUT_KEYS[ref], path)
            if ref == "joint":
                target = self._joint_ref(spec, path)
                offset = self._offset(spec, kind, path)
                if target is not None and offset is not None:
                    outputs.append(Output(name, kind, target, offset=offset))
                continue
            target = self._moving_body(spec, path)
            letter = c.string(spec, "component", path, default="x")
            component = _COMPONENTS.get(letter)
            if letter is not None and component is None:
                c.add(_join(path, "component"), f"expected x, y or z, got {letter!r}")
            point = None
            if ref == "point":
                location = self._planar_point(spec, "location", path)
                if location is None or target is None:
                    continue
                point = self._local_point(target, location)
            if target is not None and component is not None:
                outputs.append(Output(name, kind, target, component, point))
        return outputs
