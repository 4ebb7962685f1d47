"""A flat body (all its mass in one plane: principal moments A + B = C exactly) in MuJoCo, whose
compiler refuses A + B < C and so, before, refused such a body whenever round-off fell below C
("inertia must satisfy A + B >= C").  The adapter raises the two in-plane moments by 1e-9 × C,
with a note; ``mbh export`` writes it so that it reads back.

The body: a planar ternary link built from parts, two rods at an angle and a point mass (Watt's
six-bar has one), hinged at one end.  Measured (2026-11-29, dt = 1e-3 s, 0.5 s, ``best``): angle
error against the verified reference 1.9e-11 rad hinged about its normal (planar scene), 1.2e-9
rad hinged about an in-plane axis (spatial scene, where the raised moment takes part).
"""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

import mbh
from mbh._adapters.mujoco_adapter import MujocoAdapter, export_mjcf
from mbh._adapters.mujoco_adapter.build import TRIANGLE_MARGIN

#: Two rods at an angle and a point mass, in the z = 0 plane (kg, m).
PLATE = [{"type": "rod", "mass": 1.0, "length": 0.4, "axis": [1.0, 0.0, 0.0],
          "position": [0.2, 0.0, 0.0]},
         {"type": "rod", "mass": 0.7, "length": 0.3, "axis": [0.6, 0.8, 0.0],
          "position": [0.09, 0.12, 0.0]},
         {"type": "point", "mass": 0.3, "position": [0.3, 0.2, 0.0]}]

#: (scene kind, hinge axis, bound on the angle error, rad): 50× and 80× the measured errors.
CASES = [("planar", [0.0, 0.0, 1.0], 1e-9), ("spatial", [1.0, 0.0, 0.0], 1e-7)]


def flat_plate(kind: str, axis: list[float]) -> mbh.Mechanism:
    gravity = [0.0, -9.81, 0.0] if kind == "planar" else [0.0, 0.0, -9.81]
    plane = {"plane": "xy"} if kind == "planar" else {}
    return (mbh.MechanismBuilder(f"flat_plate_{kind}", kind=kind, duration=1.0, gravity=gravity,
                                 **plane)
            .body("plate", parts=PLATE)
            .joint("pivot", "revolute", body1="ground", body2="plate",
                   location=[0.0, 0.0, 0.0], axis=axis)
            .initial(driver="pivot", value=0.0, rate=0.0)
            .output("angle", "joint_angle", joint="pivot")
            .build())


def _triangle_excess(moments: np.ndarray) -> float:
    """A + B − C of principal moments ``moments`` (3,), sorted."""
    a, b, c = np.sort(moments)
    return a + b - c


def test_the_plate_is_flat_to_round_off():
    moments = np.linalg.eigvalsh(flat_plate("planar", [0.0, 0.0, 1.0]).bodies[0].inertia)
    assert abs(_triangle_excess(moments)) <= 1e-15 * moments.max()


@pytest.mark.parametrize("kind, axis, bound", CASES, ids=[case[0] for case in CASES])
def test_mujoco_runs_a_flat_body_ok_against_the_reference_with_a_note(kind, axis, bound):
    result = mbh.run_case(flat_plate(kind, axis), "mujoco", "best", dt=1e-3, t_end=0.5)
    assert result.status == "ok", result.reason
    assert result.metrics["output_errors"]["angle"] <= bound
    notes = [note for note in result.trajectory.notes if "flat" in note]
    assert len(notes) == 1 and notes[0].startswith("flat body plate (")
    planar = "a planar mechanism's joints never turn them about those axes"
    assert (planar in notes[0]) == (kind == "planar")


@pytest.mark.parametrize("kind, axis, bound", CASES, ids=[case[0] for case in CASES])
def test_mujoco_is_given_in_plane_moments_raised_by_the_margin(kind, axis, bound):
    mech = flat_plate(kind, axis)
    model = MujocoAdapter().build(mech).model
    given = model.body_inertia[model.body("plate").id]
    largest = given.max()
    assert _triangle_excess(given) == pytest.approx(TRIANGLE_MARGIN * largest, rel=1e-4)
    np.testing.assert_allclose(np.sort(given), np.linalg.eigvalsh(mech.bodies[0].inertia),
                               rtol=0, atol=TRIANGLE_MARGIN * largest)


def test_the_export_reads_back_with_the_same_mass_properties():
    mech = flat_plate("spatial", [1.0, 0.0, 0.0])
    built = MujocoAdapter().build(mech).model
    exported = mujoco.MjModel.from_xml_string(export_mjcf(mech))
    for field in ("body_mass", "body_ipos", "body_iquat", "body_inertia"):
        np.testing.assert_array_equal(getattr(exported, field), getattr(built, field))
    assert _triangle_excess(exported.body_inertia[exported.body("plate").id]) > 0.0
