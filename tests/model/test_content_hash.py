"""A mechanism's ``content_hash`` names what it is: every cache keyed by it (the assembled start,
references, traces of generated functions) must never hand one mechanism another's results.

A mechanism changed with ``dataclasses.replace`` used to keep its original's hash: a four-bar
started turning took the cached start of the one at rest, and its reference build compared a run
from the wrong start (routes 0.03 rad apart after 10 ms).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from mbh._harness.model import scenario
from mbh._harness.model.mechanism import Mechanism, data_digest
from mbh._harness.neutral.start import initial_state
from mbh._harness.store.reference_files import reference_paths


def test_a_scene_file_keeps_the_hash_of_its_text():
    mech = scenario.load("fourbar_spatial")
    assert mech.content_hash != data_digest(mech)
    assert reference_paths(mech)[0].exists()  # the shipped reference, found by that hash


def test_a_replaced_start_gets_a_hash_and_a_start_of_its_own():
    mech = scenario.load("fourbar_spatial")
    at_rest = initial_state(mech)
    turning = dataclasses.replace(mech, initial=dataclasses.replace(mech.initial, rate=-3.0))
    assert turning.content_hash != mech.content_hash
    assert reference_paths(turning)[0] != reference_paths(mech)[0]
    assert np.abs(initial_state(turning).angular_velocity).max() > 1.0
    assert np.abs(at_rest.angular_velocity).max() == 0.0


def test_what_computes_nothing_keeps_the_hash():
    mech = scenario.load("fourbar")
    assert dataclasses.replace(mech, notes="another note", tags=("x",)).content_hash \
        == mech.content_hash
    heavier = dataclasses.replace(mech, bodies=(dataclasses.replace(mech.bodies[0],
                                                                    mass=mech.bodies[0].mass * 2),
                                                *mech.bodies[1:]))
    assert heavier.content_hash != mech.content_hash


def test_a_mechanism_built_without_a_hash_gets_its_data_digest():
    mech = scenario.load("simple_pendulum")
    bare = Mechanism(**{**{f.name: getattr(mech, f.name) for f in dataclasses.fields(mech)},
                        "content_hash": "", "source_digest": ""})
    assert bare.content_hash == data_digest(mech) != ""
