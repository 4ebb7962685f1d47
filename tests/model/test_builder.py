"""The Python builder (mbh._harness.model.builder) is the file loader by other means: the same
document gives the same mechanism and hash, the same mistakes the same problems."""

import tomllib

import numpy as np
import pytest

from mbh._harness.model import scenario
from mbh._harness.model.builder import MechanismBuilder
from tests.helpers import ROOT


def fourbar_builder() -> MechanismBuilder:
    """scenarios/fourbar.toml typed as builder calls (notes and tags as in the file)."""
    document = tomllib.loads((ROOT / "scenarios" / "fourbar.toml").read_text())
    top = {key: document[key] for key in ("kind", "plane", "duration", "gravity", "tags", "notes")}
    builder = MechanismBuilder("fourbar", **top)
    for body in document["bodies"]:
        fields = dict(body)
        builder.body(fields.pop("name"), **{k: np.asarray(v) if isinstance(v, list) else v
                                            for k, v in fields.items()})
    for joint in document["joints"]:
        fields = dict(joint)
        builder.joint(fields.pop("name"), fields.pop("type"), **fields)
    for force in document["forces"]:
        fields = dict(force)
        builder.force(fields.pop("type"), **fields)
    builder.initial(**document["initial"])
    for name, output in document["outputs"].items():
        fields = dict(output)
        builder.output(name, fields.pop("kind"), **fields)
    return builder


def test_the_builder_and_the_file_give_one_mechanism_and_one_hash():
    built, loaded = fourbar_builder().build(), scenario.load("fourbar")
    assert built.content_hash == loaded.content_hash
    assert [b.name for b in built.bodies] == [b.name for b in loaded.bodies]
    for mine, theirs in zip(built.bodies, loaded.bodies):
        assert np.array_equal(mine.inertia, theirs.inertia)
        assert np.array_equal(mine.position, theirs.position)
    assert built.source == "<python: fourbar>"


def test_another_document_gets_another_hash():
    changed = fourbar_builder().force("joint_torque", joint="R", value=1.0).build()
    assert changed.content_hash != scenario.load("fourbar").content_hash


def test_mistakes_are_the_loaders_problems_naming_the_field():
    builder = MechanismBuilder("bad", kind="planar", plane="xy", duration=1.0,
                               gravity=[0.0, -9.81, 0.0])
    builder.body("bar", mass=1.0, inertia=[0.0, 1.0, 1.0], position=[0.5, 0.0, 0.0], colour="red")
    builder.joint("pivot", "revolute", body1="ground", body2="nobody", location=[0.0, 0.0, 0.0])
    with pytest.raises(scenario.ScenarioError) as raised:
        builder.build()
    fields = {(p.file, p.field) for p in raised.value.problems}
    assert ("<python: bad>", "bodies[0].colour") in fields
    assert ("<python: bad>", "joints[0].body2") in fields


def test_the_document_is_a_copy():
    builder = fourbar_builder()
    builder.document()["bodies"].clear()
    assert len(builder.build().bodies) == 3
