"""Loading and validating scenario files (TOML, one mechanism per file in ``scenarios/``).

The validator walks the whole file, collects every problem with its field path and raises one
:class:`ScenarioError` listing them all (the sympy.physics.mechanics style), so a user fixes a file
in one pass.  Nothing here raises anything else for bad input.

File format (all SI; angles in degrees only where the key says ``_deg``)::

    kind = "planar"               # or "spatial"
    plane = "xy"                  # planar only
    duration = 4.0                # s
    gravity = [0.0, -9.81, 0.0]   # m/s², world
    tags = ["seed"]
    notes = "free text: sources, typos found in them"

    [[bodies]]                    # centre-of-mass frame, reference configuration
    name = "crank"
    mass = 78.1
    inertia = [Ixx, Iyy, Izz]     # or [Ixx, Iyy, Izz, Ixy, Ixz, Iyz], kg·m², body frame
    position = [x, y, z]
    angle_deg = 60.0              # planar; spatial: euler313_deg = [ψ, θ, φ] or quaternion = [w, x, y, z]

    [[joints]]
    name = "O"
    type = "revolute"             # revolute prismatic spherical universal cylindrical translational
    body1 = "ground"
    body2 = "crank"
    location = [0, 0, 0]          # world, reference configuration
    location2 = [...]             # optional: body2's point when the drawing is not assembled
    axis = [0, 0, 1]              # world; universal: body1's cross axis
    axis2 = [...]                 # universal: body2's cross axis
    normal = [...]                # optional: perpendicular giving the zero of the joint angle

    [[forces]]
    type = "joint_torque"         # joint_torque joint_force body_force body_torque spring_damper
    joint = "O"
    value = -1200.0

    [initial]
    driver = "O"                  # a revolute, cylindrical, prismatic or translational joint
    value = 0.0                   # rad or m from the reference configuration
    rate = 0.0                    # rad/s or m/s
    guess = { coupler = [x, y, z] }   # optional Newton start: picks the assembly branch

    [outputs]
    crank_angle = { kind = "joint_angle", joint = "O" }
    slider_x = { kind = "position", body = "slider", component = "x" }
"""

from __future__ import annotations

import hashlib
import json
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from harness.model import (
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
    SpringDamper,
)

SCENARIO_DIR = Path(__file__).resolve().parent.parent / "scenarios"

_TOP_KEYS = {"name", "kind", "plane", "duration", "gravity", "tags", "notes", "bodies", "joints",
             "forces", "initial", "outputs"}
_BODY_KEYS = {"name", "mass", "inertia", "position", "angle_deg", "euler313_deg", "quaternion"}
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
                 "position": "body", "velocity": "body"}
_COMPONENTS = {"x": 0, "y": 1, "z": 2}
_AXIS_TOL = 1e-9


@dataclass(frozen=True)
class Problem:
    """One validation finding: ``file: field: message``."""

    file: str
    field: str
    message: str

    def __str__(self) -> str:
        return f"{self.file}: {self.field}: {self.message}"


class ScenarioError(ValueError):
    """Raised once per file with every :class:`Problem` found."""

    def __init__(self, problems: list[Problem]):
        self.problems = problems
        super().__init__("\n".join(str(p) for p in problems))


class _Collector:
    """Typed field readers that record a problem instead of raising."""

    def __init__(self, file: str):
        self.file = file
        self.problems: list[Problem] = []

    def add(self, field: str, message: str) -> None:
        self.problems.append(Problem(self.file, field, message))

    def unknown_keys(self, table: dict, allowed: set[str], path: str) -> None:
        for key in sorted(set(table) - allowed):
            self.add(f"{path}.{key}" if path else key,
                     f"unknown key (allowed: {', '.join(sorted(allowed))})")

    def required(self, table: dict, key: str, path: str) -> Any:
        if key not in table:
            self.add(_join(path, key), "missing required field")
            return None
        return table[key]

    def string(self, table: dict, key: str, path: str, default: str | None = None) -> str | None:
        value = table.get(key, default) if default is not None else self.required(table, key, path)
        if value is None:
            return None
        if not isinstance(value, str) or not value:
            self.add(_join(path, key), f"expected a non-empty string, got {value!r}")
            return None
        return value

    def number(self, table: dict, key: str, path: str, default: float | None = None,
               positive: bool = False, nonnegative: bool = False) -> float | None:
        value = table.get(key, default) if default is not None else self.required(table, key, path)
        if value is None:
            return None
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            self.add(_join(path, key), f"expected a finite number, got {value!r}")
            return None
        if positive and value <= 0:
            self.add(_join(path, key), f"must be > 0, got {value!r}")
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
        array = np.asarray(value, dtype=float)
        if not np.all(np.isfinite(array)):
            self.add(field, f"contains a non-finite value: {value!r}")
            return None
        if nonzero and np.linalg.norm(array) < _AXIS_TOL:
            self.add(field, "zero-length vector")
            return None
        return array


def _missing(*values) -> bool:
    """True if any value is None (arrays compare element-wise, so ``None in`` cannot be used)."""
    return any(v is None for v in values)


def _join(path: str, key: str) -> str:
    return f"{path}.{key}" if path else key


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
    """Why ``tensor`` is not a physical inertia tensor, or None."""
    principal = np.linalg.eigvalsh(tensor)
    if principal[0] <= 0:
        return f"not positive definite (principal moments {principal.tolist()})"
    total = principal.sum()
    for moment in principal:
        if moment > total - moment + 1e-12 * total:
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


def load(name_or_path: str | Path) -> Mechanism:
    """Load and validate a scenario by shipped name or by path.

    Raises
    ------
    ScenarioError
        With every problem found, each naming the file and the field.
    """
    path = Path(name_or_path)
    if path.suffix != ".toml":
        path = scenario_path(str(name_or_path))
    file = str(path)
    try:
        document = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        known = ", ".join(scenario_names())
        raise ScenarioError([Problem(file, "-", f"no such scenario file (shipped: {known})")]) from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as error:
        raise ScenarioError([Problem(file, "-", f"not valid TOML: {error}")]) from None
    return _Builder(file, path.stem, document).build()


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
        name = c.string(doc, "name", "", default=self.stem)
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
        forces = self._forces()
        initial = self._initial()
        outputs = self._outputs()
        if c.problems:
            raise ScenarioError(c.problems)
        return Mechanism(
            name=name, kind=kind, bodies=tuple(self.bodies.values()),
            joints=tuple(self.joints.values()), forces=tuple(forces), gravity=gravity,
            initial=initial, duration=duration, outputs=tuple(outputs), tags=tuple(tags),
            notes=notes, source=c.file, content_hash=_hash(doc),
        )

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
        name = self.c.string(table, "name", path)
        if name is None:
            return None
        if name in seen or name in reserved:
            self.c.add(_join(path, "name"), f"duplicate name {name!r}")
            return None
        return name

    def _bodies(self) -> None:
        c = self.c
        for path, table in self._tables("bodies", required=True):
            c.unknown_keys(table, _BODY_KEYS, path)
            name = self._unique_name(table, path, self.bodies, reserved=(GROUND,))
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
            rotation = self._orientation(table, path)
            if self.planar and position is not None and position[2] != 0.0:
                c.add(_join(path, "position"), "a planar body must lie in z = 0")
            if not _missing(name, mass, inertia, position, rotation):
                self.bodies[name] = Body(name, mass, inertia, position, rotation)
            elif name is not None:
                self.bodies[name] = None  # known name, invalid body: keeps references quiet

    def _orientation(self, table: dict, path: str) -> np.ndarray | None:
        c = self.c
        given = [k for k in ("angle_deg", "euler313_deg", "quaternion") if k in table]
        if len(given) > 1:
            c.add(path, f"give one orientation, not {', '.join(given)}")
            return None
        if self.planar:
            if given and given[0] != "angle_deg":
                c.add(_join(path, given[0]), "a planar body takes angle_deg")
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
        c.add(_join(path, "angle_deg"), "a spatial body takes euler313_deg or quaternion")
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
            normal = _perpendicular(axis) if normal is None else normal
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

    def _joint_ref(self, table: dict, path: str, types=None) -> str | None:
        name = self.c.string(table, "joint", path)
        if name is None:
            return None
        if name not in self.joints:
            self.c.add(_join(path, "joint"), f"unknown joint {name!r} (known: {', '.join(self.joints)})")
            return None
        joint = self.joints[name]
        if types is not None and joint is not None and joint.type not in types:
            self.c.add(_join(path, "joint"), f"joint {name!r} is {joint.type}; expected one of "
                       f"{', '.join(types)}")
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
        name = c.string(table, "name", path, default="spring")
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
        c.unknown_keys(table, {"driver", "value", "rate", "guess"}, "initial")
        driver = c.string(table, "driver", "initial")
        if driver is not None:
            joint = self.joints.get(driver, 0)
            if driver not in self.joints:
                c.add("initial.driver", f"unknown joint {driver!r} (known: {', '.join(self.joints)})")
                driver = None
            elif joint is not None and joint.type not in DRIVABLE:
                c.add("initial.driver", f"joint {driver!r} is {joint.type}, which has no single "
                      f"coordinate; drivable types: {', '.join(DRIVABLE)}")
                driver = None
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
        if _missing(driver, value, rate):
            return None
        return InitialState(driver, value, rate, guess)

    def _outputs(self) -> list[Output]:
        c = self.c
        table = self.doc.get("outputs", {})
        if not isinstance(table, dict):
            c.add("outputs", "expected a table of name = { kind = ..., ... }")
            return []
        outputs = []
        for name, spec in table.items():
            path = f"outputs.{name}"
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
            allowed = {"kind", ref} | ({"component"} if ref == "body" else set())
            c.unknown_keys(spec, allowed, path)
            if ref == "joint":
                target = self._joint_ref(spec, path)
                component = 0
            else:
                target = self._body_ref(spec, "body", path)
                letter = c.string(spec, "component", path, default="x")
                component = _COMPONENTS.get(letter)
                if component is None:
                    c.add(_join(path, "component"), f"expected x, y or z, got {letter!r}")
            if target is not None and component is not None:
                outputs.append(Output(name, kind, target, component))
        return outputs
