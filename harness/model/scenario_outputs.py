"""The ``[outputs]`` and ``[reference]`` sections of a scenario file: the outputs of interest a run
is measured by (joint angles, rates and positions, body and point positions and velocities), and
how the reference is computed (the joint pairs that turn by equal angles on the motion's branch,
and the routes it takes).
"""

from __future__ import annotations

from mbh._harness.model.mechanism import Output
from mbh._harness.model.scenario_reader import COMPONENTS, ScenarioReader
from mbh._harness.model.toml_fields import _join, name_problem

__all__ = ["read_outputs", "read_reference"]

#: What each output kind names: a joint, a body or a point of a body.
_OUTPUT_KINDS = {"joint_angle": "joint", "joint_rate": "joint", "joint_position": "joint",
                 "position": "body", "velocity": "body",
                 "point_position": "point", "point_velocity": "point"}
_OUTPUT_KEYS = {"joint": {"kind", "joint", "offset"}, "body": {"kind", "body", "component"},
                "point": {"kind", "body", "location", "component"}}


def read_outputs(reader: ScenarioReader) -> list[Output]:
    """The valid ``[outputs]`` (the bodies and joints are read)."""
    c = reader.c
    table = reader.doc.get("outputs", {})
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
            target = reader.joint_ref(spec, path)
            offset = _offset(reader, spec, kind, path)
            if target is not None and offset is not None:
                outputs.append(Output(name, kind, target, offset=offset))
            continue
        target = reader.moving_body(spec, path)
        letter = c.string(spec, "component", path, default="x")
        component = COMPONENTS.get(letter)
        if letter is not None and component is None:
            c.add(_join(path, "component"), f"expected x, y or z, got {letter!r}")
        point = None
        if ref == "point":
            location = reader.planar_point(spec, "location", path)
            if location is None or target is None:
                continue
            point = reader.local_point(target, location)
        if target is not None and component is not None:
            outputs.append(Output(name, kind, target, component, point))
    return outputs


def _offset(reader: ScenarioReader, spec: dict, kind: str, path: str) -> float | None:
    """A joint output's ``offset`` (rad, default 0): only ``joint_angle`` takes one."""
    if "offset" in spec and kind != "joint_angle":
        reader.c.add(_join(path, "offset"),
                     f"only joint_angle outputs take an offset, not {kind}")
        return None
    return reader.c.number(spec, "offset", path, default=0.0)


def read_reference(reader: ScenarioReader) -> tuple[tuple[tuple[str, str], ...], bool]:
    """The ``[reference]`` table: pairs of revolute or cylindrical joints that turn by equal
    angles on the motion's assembly branch, and whether the reference takes the neutral
    routes (``routes = "neutral"``; the default ``"inhouse"``)."""
    c = reader.c
    table = reader.doc.get("reference", {})
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
        known = [reader.known_joint(name, path, ("revolute", "cylindrical"),
                                    ", which has no angle") for name in pair]
        if all(known):
            branch.append((pair[0], pair[1]))
    return tuple(branch), routes == "neutral"
