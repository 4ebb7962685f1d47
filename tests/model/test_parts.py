"""Bodies from parts: closed-form part inertias, their combination by the parallel-axis theorem,
the loader's ``parts`` field and its problems, and the check that a body's joints hold the turns
it has no inertia against (harness/model/parts.py, harness/model/free_turns.py).

Round-off: every expected value here is exact or a few operations on exact values; 1e-15
relative is ten times the largest difference measured (1.1e-16 kg·m² on moments of order 1).
"""

from __future__ import annotations

import json
import math
import tomllib

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mbh._harness.model import parts
from mbh._harness.model.scenario import ScenarioError, from_document, load

ROUND_OFF = 1e-15


def close(actual, expected) -> bool:
    return np.allclose(actual, expected, rtol=ROUND_OFF, atol=ROUND_OFF)


# -- closed forms of each part ----------------------------------------------------------------

def test_a_point_mass_has_no_inertia_about_itself():
    part = parts.point(2.5, np.array([1.0, -2.0, 3.0]))
    assert part.mass == 2.5 and np.array_equal(part.centre, [1.0, -2.0, 3.0])
    assert not part.inertia.any()


def test_a_rod_has_m_l2_over_12_across_it_and_nothing_about_its_axis():
    rod = parts.rod(3.0, 2.0, np.zeros(3), np.array([0.0, 0.0, 5.0]))  # axis of any length
    assert close(rod.inertia, np.diag([1.0, 1.0, 0.0]))  # 3 · 2² / 12 = 1


def test_a_box_has_m_over_12_times_the_other_two_edges_squared():
    box = parts.box(12.0, np.array([1.0, 2.0, 3.0]), np.zeros(3), np.eye(3))
    assert close(box.inertia, np.diag([4.0 + 9.0, 1.0 + 9.0, 1.0 + 4.0]))


def test_a_box_turned_a_quarter_about_z_swaps_its_x_and_y_moments():
    turned = Rotation.from_euler("z", 90.0, degrees=True).as_matrix()
    box = parts.box(12.0, np.array([1.0, 2.0, 3.0]), np.zeros(3), turned)
    assert close(box.inertia, np.diag([10.0, 13.0, 5.0]))


def test_a_rotated_box_keeps_its_moments_and_a_cube_is_isotropic():
    turn = Rotation.from_euler("ZXZ", [30.0, 40.0, 50.0], degrees=True).as_matrix()
    box = parts.box(12.0, np.array([1.0, 2.0, 3.0]), np.zeros(3), turn)
    assert close(np.linalg.eigvalsh(box.inertia), [5.0, 10.0, 13.0])
    assert close(box.inertia @ turn[:, 2], 5.0 * turn[:, 2])  # the 3 m edge is a principal axis
    cube = parts.box(6.0, np.array([2.0, 2.0, 2.0]), np.zeros(3), turn)
    assert close(cube.inertia, 4.0 * np.eye(3))  # 6/12 · (4 + 4)


def test_a_cylinder_has_m_r2_over_2_about_its_axis_and_m_3r2_l2_over_12_across():
    cylinder = parts.cylinder(12.0, 1.0, 3.0, np.zeros(3), np.array([1.0, 0.0, 0.0]))
    assert close(cylinder.inertia, np.diag([6.0, 12.0, 12.0]))  # 12/12 · (3 + 9)


def test_a_cylinder_on_a_slanted_axis_is_the_aligned_one_turned():
    axis = np.array([1.0, 1.0, 1.0]) / math.sqrt(3.0)
    slanted = parts.cylinder(12.0, 1.0, 3.0, np.zeros(3), 7.0 * axis)
    turn = Rotation.align_vectors([axis], [[1.0, 0.0, 0.0]])[0].as_matrix()
    assert close(slanted.inertia, turn @ np.diag([6.0, 12.0, 12.0]) @ turn.T)


def test_a_sphere_has_two_fifths_m_r2():
    assert close(parts.sphere(5.0, 2.0, np.zeros(3)).inertia, 8.0 * np.eye(3))


def test_volumes_give_the_mass_of_a_density():
    assert parts.box_volume(np.array([2.0, 3.0, 4.0])) == 24.0
    assert close(parts.cylinder_volume(2.0, 3.0), 12.0 * math.pi)
    assert close(parts.sphere_volume(3.0), 36.0 * math.pi)


# -- the parallel-axis theorem ----------------------------------------------------------------

def test_an_offset_adds_m_d2_across_it_and_minus_m_di_dj_off_the_diagonal():
    shifted = parts.shifted(np.eye(3), 2.0, np.array([1.0, 2.0, 0.0]))
    assert close(shifted, np.eye(3) + 2.0 * np.array([[4.0, -2.0, 0.0], [-2.0, 1.0, 0.0],
                                                       [0.0, 0.0, 5.0]]))


@pytest.mark.parametrize("halves, whole", [
    ((parts.rod(1.0, 1.0, np.array([0.5, 0.0, 0.0]), np.array([1.0, 0.0, 0.0])),
      parts.rod(1.0, 1.0, np.array([1.5, 0.0, 0.0]), np.array([1.0, 0.0, 0.0]))),
     parts.rod(2.0, 2.0, np.array([1.0, 0.0, 0.0]), np.array([1.0, 0.0, 0.0]))),
    ((parts.box(1.0, np.array([1.0, 2.0, 3.0]), np.array([2.5, 1.0, 1.0]), np.eye(3)),
      parts.box(1.0, np.array([1.0, 2.0, 3.0]), np.array([3.5, 1.0, 1.0]), np.eye(3))),
     parts.box(2.0, np.array([2.0, 2.0, 3.0]), np.array([3.0, 1.0, 1.0]), np.eye(3))),
    ((parts.cylinder(1.0, 1.0, 1.0, np.array([0.0, 0.0, -0.5]), np.array([0.0, 0.0, 1.0])),
      parts.cylinder(1.0, 1.0, 1.0, np.array([0.0, 0.0, 0.5]), np.array([0.0, 0.0, 1.0]))),
     parts.cylinder(2.0, 1.0, 2.0, np.zeros(3), np.array([0.0, 0.0, 1.0]))),
])
def test_two_off_centre_halves_combine_into_the_whole(halves, whole):
    """Each half sits off the whole's centre (off-axis placement), so the sum holds only with the
    parallel-axis terms."""
    combined = parts.combined(halves)
    assert combined.mass == whole.mass
    assert close(combined.centre, whole.centre)
    assert close(combined.inertia, whole.inertia)


def test_a_rod_with_a_point_mass_at_its_end_matches_the_hand_computation():
    """A 2 kg, 1 m rod from the origin along x and 1 kg at its end: M = 3 kg, c = (2·0.5 + 1)/3
    = 2/3 m; about c, rod 2/12 + 2 (1/2 − 2/3)² = 2/9 and point 1 · (1/3)² = 1/9, so 1/3 kg·m²
    across the rod (= 5/3 about the origin − 3 (2/3)²) and none about it."""
    x = np.array([1.0, 0.0, 0.0])
    body = parts.combined([parts.rod(2.0, 1.0, 0.5 * x, x), parts.point(1.0, x)])
    assert body.mass == 3.0
    assert close(body.centre, [2.0 / 3.0, 0.0, 0.0])
    assert close(body.inertia, np.diag([0.0, 1.0 / 3.0, 1.0 / 3.0]))


# -- the loader -------------------------------------------------------------------------------

def document(body: str, joints: str, kind: str = "planar") -> dict:
    """A scene of body ``arm`` (its table's keys given as TOML) on ``joints`` (TOML tables),
    beside a driven wheel on a revolute ``drive`` (so the arm's joints need not be drivable)."""
    plane = 'plane = "xy"\n' if kind == "planar" else ""
    return tomllib.loads(f"""
kind = "{kind}"
{plane}duration = 1.0
gravity = [0.0, -9.81, 0.0]
[[bodies]]
name = "wheel"
parts = [{{ type = "cylinder", mass = 1.0, radius = 0.1, length = 0.1, axis = [0.0, 0.0, 1.0], position = [0.0, 2.0, 0.0] }}]
[[joints]]
name = "drive"
type = "revolute"
body1 = "ground"
body2 = "wheel"
location = [0.0, 2.0, 0.0]
axis = [0.0, 0.0, 1.0]
[[bodies]]
name = "arm"
{body}
{joints}
[initial]
driver = "drive"
[outputs]
angle = {{ kind = "joint_angle", joint = "drive" }}
""")


PIVOT = """[[joints]]
name = "pivot"
type = "revolute"
body1 = "ground"
body2 = "arm"
location = [0.0, 0.0, 0.0]
"""
ROD_AND_BOB = """[[bodies.parts]]
type = "rod"
density = 2.0
length = 1.0
axis = [1.0, 0.0, 0.0]
position = [0.5, 0.0, 0.0]
[[bodies.parts]]
type = "point"
mass = 1.0
position = [1.0, 0.0, 0.0]
"""


def build(body: str, joints: str = PIVOT, kind: str = "planar"):
    return from_document(document(body, joints, kind), "arm", "arm.toml")


def problems(body: str, joints: str = PIVOT, kind: str = "planar") -> dict[str, str]:
    with pytest.raises(ScenarioError) as raised:
        build(body, joints, kind)
    return {p.field: p.message for p in raised.value.problems}


def test_a_body_of_parts_is_the_body_written_by_hand():
    """The rod (2 kg/m × 1 m) and bob above, and the same body as mass, inertia and position."""
    from_parts = build(ROD_AND_BOB).bodies[1]
    by_hand = build("mass = 3.0\ninertia = [0.0, 0.3333333333333333, 0.3333333333333333]\n"
                    "position = [0.6666666666666666, 0.0, 0.0]").bodies[1]
    assert from_parts.mass == by_hand.mass
    assert close(from_parts.position, by_hand.position)
    assert close(from_parts.inertia, by_hand.inertia)
    assert np.array_equal(from_parts.rotation, np.eye(3))


def test_the_inertia_of_parts_is_stored_in_the_body_frame():
    """Parts are placed in world coordinates; a body frame turned by 90° about z sees the rod
    (along world x) along its own −y."""
    quarter = build("angle_deg = 90.0\n" + ROD_AND_BOB).bodies[1]
    assert close(quarter.position, [2.0 / 3.0, 0.0, 0.0])
    assert close(quarter.inertia, np.diag([1.0 / 3.0, 0.0, 1.0 / 3.0]))


def test_densities_of_the_solids_are_per_volume():
    body = build('parts = [{ type = "sphere", density = 1000.0, radius = 0.1, '
                 'position = [1.0, 0.0, 0.0] }]').bodies[1]
    mass = 1000.0 * 4.0 / 3.0 * math.pi * 0.1 ** 3
    assert close(body.mass, mass)
    assert close(body.inertia, 0.4 * mass * 0.01 * np.eye(3))


def test_parts_hash_as_written():
    """The content hash is of the document, so a body of parts and the same body by hand are
    two scenarios (two references), though they build equal bodies."""
    from_parts = build(ROD_AND_BOB)
    by_hand = build("mass = 3.0\ninertia = [0.0, 0.3333333333333333, 0.3333333333333333]\n"
                    "position = [0.6666666666666666, 0.0, 0.0]")
    assert from_parts.content_hash != by_hand.content_hash


def test_every_part_problem_is_reported_at_once():
    found = problems("""mass = 1.0
inertia = [1.0, 1.0, 1.0]
position = [0.0, 0.0, 0.0]
parts = [
  { type = "blob", mass = 1.0, position = [0.0, 0.0, 0.0] },
  { type = "rod", mass = 1.0, density = 2.0, length = 1.0, axis = [1.0, 0.0, 0.0], position = [0.5, 0.0, 0.0] },
  { type = "rod", length = 1.0, axis = [0.0, 0.0, 0.0], position = [0.5, 0.0, 0.0] },
  { type = "box", density = 7800.0, size = [0.1, 0.0, 0.1], euler313_deg = [0.0, 0.0, 0.0], position = [0.0, 0.0, 0.0] },
  { type = "cylinder", mass = 1.0, radius = -0.1, length = 1.0, position = [0.0, 0.0, 0.5] },
  { type = "sphere", mass = 1.0, position = [0.0, 0.0, 0.0] },
  { type = "point", density = 1.0, position = [1.0, 0.0, 0.0] },
]""")
    assert found == {
        "bodies[1].mass": "not with parts: the mass, centre of mass and inertia of a body of parts "
                          "are computed from its parts",
        "bodies[1].inertia": found["bodies[1].mass"],
        "bodies[1].position": found["bodies[1].mass"],
        "bodies[1].parts[0].type": "unknown part type 'blob' (known: point, rod, box, cylinder, "
                                   "sphere)",
        "bodies[1].parts[1]": "give mass or density, not both",
        "bodies[1].parts[2].axis": "zero-length vector",
        "bodies[1].parts[2].mass": "missing: give mass (kg) or density (kg/m)",
        "bodies[1].parts[3].size": "edge lengths must be > 0, got [0.1, 0.0, 0.1]",
        "bodies[1].parts[3].euler313_deg": "a planar box takes angle_deg",
        "bodies[1].parts[4].radius": "must be > 0, got -0.1",
        "bodies[1].parts[4].axis": "missing required field",
        "bodies[1].parts[4].position": "a planar scene lies in z = 0",
        "bodies[1].parts[5].radius": "missing required field",
        "bodies[1].parts[6].density": "unknown key (allowed: mass, position, type)",
        "bodies[1].parts[6].mass": "missing required field",
    }


@pytest.mark.parametrize("value", ["[]", "3.0", '["rod"]'])
def test_parts_must_be_a_list_of_tables(value):
    assert problems(f"parts = {value}") == {"bodies[1].parts": (
        "expected a non-empty array of tables, one per part ([[bodies.parts]] or a list of "
        "inline tables)")}


def test_a_density_giving_no_mass_is_named():
    found = problems('parts = [{ type = "sphere", density = 1e-90, radius = 1e-20, '
                     'position = [1.0, 0.0, 0.0] }]')
    assert found["bodies[1].parts[0].density"].startswith("gives a mass of 4.18879e-150 kg")


# -- zero moments held by the joints ----------------------------------------------------------

BOB = 'parts = [{ type = "point", mass = 1.0, position = [1.0, 0.0, 0.0] }]'


def spatial_joint(kind: str, location="[0.0, 0.0, 0.0]", extra: str = "") -> str:
    return (f'[[joints]]\nname = "pivot"\ntype = "{kind}"\nbody1 = "ground"\nbody2 = "arm"\n'
            f'location = {location}\n{extra}')


def test_a_point_mass_on_a_revolute_away_from_it_loads():
    assert not build(BOB).bodies[1].inertia.any()
    assert not build(BOB, spatial_joint("revolute", extra="axis = [0.0, 0.0, 1.0]"),
                     kind="spatial").bodies[1].inertia.any()


def test_a_point_mass_given_as_zero_inertia_loads():
    assert build("mass = 1.0\ninertia = [0.0, 0.0, 0.0]\nposition = [1.0, 0.0, 0.0]").bodies


@pytest.mark.parametrize("joint, kind, field, axis", [
    (PIVOT.replace("[0.0, 0.0, 0.0]", "[1.0, 0.0, 0.0]"), "planar", "parts", [0.0, 0.0, 1.0]),
    (spatial_joint("spherical"), "spatial", "parts", [1.0, 0.0, 0.0]),
    (spatial_joint("revolute", extra="axis = [1.0, 0.0, 0.0]"), "spatial", "parts",
     [1.0, 0.0, 0.0]),
    (spatial_joint("universal", extra="axis = [1.0, 0.0, 0.0]\naxis2 = [0.0, 1.0, 0.0]"),
     "spatial", "parts", [1.0, 0.0, 0.0]),
])
def test_a_point_mass_free_to_turn_is_refused(joint, kind, field, axis):
    """On its own centre (planar); on a ball joint (the turn about the line to the joint); on a
    revolute or a universal whose cross axes hold the line to the joint."""
    found = problems(BOB, joint, kind)
    message = found.pop(f"bodies[1].{field}")
    assert not found
    turn = np.array(json.loads(message.split("axis ")[1].split(" through")[0]))
    assert close(abs(turn @ axis), 1.0), message
    assert "its joints leave that turn free, so its motion is undetermined" in message


def test_a_point_mass_on_a_universal_across_its_arm_loads():
    joint = spatial_joint("universal", extra="axis = [0.0, 1.0, 0.0]\naxis2 = [0.0, 0.0, 1.0]")
    assert build(BOB, joint, kind="spatial").bodies


def test_a_joint_with_problems_is_not_echoed_as_a_free_turn():
    found = problems(BOB, PIVOT.replace('body2 = "arm"', 'body2 = "nobody"'))
    assert list(found) == ["joints[1].body2"]


def test_a_slender_bar_between_two_ball_joints_is_refused():
    """The classic free spin of a connecting rod with ball ends, when it has no moment about its
    own axis."""
    bar = "mass = 1.0\ninertia = [0.0, 0.08333, 0.08333]\nposition = [0.5, 0.0, 0.0]"
    joints = (spatial_joint("spherical") + spatial_joint("spherical", "[1.0, 0.0, 0.0]")
              .replace('"pivot"', '"end"'))
    found = problems(bar, joints, kind="spatial")
    assert list(found) == ["bodies[1].inertia"]
    assert "axis [1.0, 0.0, 0.0]" in found["bodies[1].inertia"] \
        or "axis [-1.0, 0.0, 0.0]" in found["bodies[1].inertia"]


def test_the_shipped_simple_pendulum_is_a_point_mass_on_a_massless_link():
    pendulum = load("simple_pendulum")
    bob, = pendulum.bodies
    assert (bob.mass, bob.position.tolist()) == (1.0, [1.0, 0.0, 0.0])
    assert not bob.inertia.any()
    assert pendulum.joints[0].point2.tolist() == [-1.0, 0.0, 0.0]
