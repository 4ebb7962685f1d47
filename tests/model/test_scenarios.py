"""Scenario loading and validation: every problem reported at once, with file and field."""

from __future__ import annotations

import numpy as np
import pytest

from scipy.spatial.transform import Rotation

from mbh._harness import cli

from mbh._harness.model import scenario
from mbh._harness.model.mechanism import PrescribedJointRate, PrescribedPointVelocity
from mbh._harness.model.outputs import output_series
from mbh._harness.model.scenario import ScenarioError
from mbh._harness.model.scenario_bodies import inertia_problem
from mbh._harness.model.trajectory import Trajectory

BAD = """
kind = "spatial"
duration = "four seconds"
gravity = [0.0, -9.81]
[[bodies]]
name = "crank"
mass = -1.0
inertia = [1.0, 1.0, 5.0]
position = [0.0, 0.0, 0.0]
[[bodies]]
name = "crank"
mass = 1.0
inertia = [1.0, -2.0, 1.0]
position = [1.0, 0.0, 0.0]
[[joints]]
name = "O"
type = "hinge"
body1 = "ground"
body2 = "crank"
location = [0.0, 0.0, 0.0]
[[joints]]
name = "A"
type = "revolute"
body1 = "crank"
body2 = "nobody"
location = [0.0, 0.0, 0.0]
axis = [0.0, 0.0, 0.0]
"""

EXPECTED = [
    ("duration", "expected a finite number"),
    ("gravity", "expected a list of 3 numbers"),
    ("bodies[0].mass", "must be > 0"),
    ("bodies[0].inertia", "triangle inequality"),
    ("bodies[1].name", "duplicate name 'crank'"),
    ("bodies[1].inertia", "negative principal moment"),
    ("joints[0].type", "unknown spatial joint type 'hinge'"),
    ("joints[1].body2", "unknown body 'nobody'"),
    ("joints[1].axis", "zero-length vector"),
    ("initial", "missing required section"),
]


def test_every_problem_is_reported_at_once_with_file_and_field(write_scenario):
    path = write_scenario("broken", BAD)
    with pytest.raises(ScenarioError) as error:
        scenario.load(path)
    problems = error.value.problems
    assert all(p.file == str(path) for p in problems)
    found = {(p.field, p.message) for p in problems}
    for field, fragment in EXPECTED:
        assert any(f == field and fragment in m for f, m in found), (field, fragment, found)


def test_missing_driver_and_wrong_driver_type(load_variant):
    with pytest.raises(ScenarioError) as error:
        load_variant("fourbar_spatial", [('driver = "O"', 'driver = "B"')])
    assert any(p.field == "initial.driver" and "spherical" in p.message for p in error.value.problems)
    with pytest.raises(ScenarioError) as error:
        load_variant("fourbar", [('driver = "O"\n', '')])
    assert any(p.field == "initial.driver" and "missing" in p.message for p in error.value.problems)


def test_not_toml_and_unknown_file(write_scenario, tmp_path):
    with pytest.raises(ScenarioError, match="not valid TOML"):
        scenario.load(write_scenario("garbage", "kind = = ="))
    with pytest.raises(ScenarioError, match="no such scenario file"):
        scenario.load("no_such_scenario")


def test_cli_reports_bad_file_without_traceback(write_scenario, capsys):
    path = write_scenario("broken", BAD)
    status = cli.main(["check", str(path)])
    out = capsys.readouterr()
    assert status != 0
    assert "Traceback" not in out.out + out.err
    assert f"{path}: bodies[0].mass: must be > 0" in out.out + out.err


SEED_SCENARIOS = ("fourbar", "fourbar_spatial", "slider_crank", "slider_crank_planar")


@pytest.mark.parametrize("name", SEED_SCENARIOS)
def test_seed_scenarios_declare_the_required_outputs(name):
    mech = scenario.load(name)
    names = {o.name for o in mech.outputs}
    assert {"crank_angle", "crank_rate"} <= names
    if "slider" in name:
        assert "slider_x" in names


def test_fourbar_parameters_follow_seeds():
    mech = scenario.load("fourbar")
    crank = mech.bodies[mech.body_index("crank")]
    assert crank.mass == 78.1 and crank.inertia[2, 2] == 26.0496
    coupler = mech.bodies[mech.body_index("coupler")]
    b, c = mech.joint("B").point2, mech.joint("C").point1
    assert abs(np.linalg.norm(b - c) - 4.0) < 1e-14 and coupler.mass == 156.2
    assert "16.0" in mech.notes  # the table-5 typo is recorded


def test_content_hash_changes_with_content(load_variant):
    original = scenario.load("fourbar")
    changed = load_variant("fourbar", [("value = -1200.0", "value = -1100.0")], stem="fourbar")
    assert original.content_hash != changed.content_hash


#: The shipped references are keyed by these hashes (scenarios/references/<name>-<hash[:16]>-v*.npz);
#: extending the format must not change them.
SHIPPED_HASHES = {
    "fourbar": "d88d8a37006896e6b8436a62b01ea87ca2ed220bb3145d5ea5018ce385e9675b",
    "fourbar_spatial": "105832ae29e66294df8126199a516d3363ffc1f79b02f7f9fb1d3d9e5f51f530",
    "slider_crank": "ebd892755a681dce534e01e668b0514626f8bb325b580394e705b726ff9f061b",
    "slider_crank_planar": "85062f31ec6603b5166ade9779de630d55251740c646802e4cd5f4e87a5ad0e6",
}


@pytest.mark.parametrize("name", SEED_SCENARIOS)
def test_seed_scenario_hashes_are_unchanged(name):
    assert scenario.load(name).content_hash == SHIPPED_HASHES[name]


def _problems(load_variant, name, replacements) -> set[tuple[str, str]]:
    with pytest.raises(ScenarioError) as error:
        load_variant(name, replacements)
    return {(p.field, p.message) for p in error.value.problems}


def _has(problems, field, fragment) -> bool:
    return any(f == field and fragment in m for f, m in problems)


# -- point outputs ----------------------------------------------------------------------------
TIP = ('crank_rate = { kind = "joint_rate", joint = "O" }',
       'crank_rate = { kind = "joint_rate", joint = "O" }\n'
       'tip_x = { kind = "point_position", body = "crank", '
       'location = [1.0, 1.7320508075688772, 0.0] }\n'
       'tip_vx = { kind = "point_velocity", body = "crank", '
       'location = [1.0, 1.7320508075688772, 0.0], component = "x" }\n'
       'tip_vy = { kind = "point_velocity", body = "crank", '
       'location = [1.0, 1.7320508075688772, 0.0], component = "y" }')


def _rest_trajectory(mech, omega: float) -> Trajectory:
    """One sample at the reference configuration, crank turning about O at ``omega`` rad/s."""
    nb = len(mech.bodies)
    position = np.array([[b.position for b in mech.bodies]])
    quaternion = np.array([[Rotation.from_matrix(b.rotation).as_quat(scalar_first=True)
                            for b in mech.bodies]])
    velocity, angular = np.zeros((1, nb, 3)), np.zeros((1, nb, 3))
    crank = mech.body_index("crank")
    angular[0, crank] = [0.0, 0.0, omega]
    velocity[0, crank] = np.cross(angular[0, crank], position[0, crank])
    return Trajectory(np.zeros(1), position, quaternion, velocity, angular)


def test_point_outputs_give_the_point_in_world(load_variant):
    mech = load_variant("fourbar", [TIP])
    tip = mech.output("tip_x")
    # B = (1, √3) lies 1 m along the crank's local x from its centre (0.5, √3/2); the loader's
    # conversion is off by 1.9e-16 (measured) in y, so 1e-15 bounds round-off only.
    assert tip.target == "crank" and tip.component == 0
    assert np.allclose(tip.point, [1.0, 0.0, 0.0], atol=1e-15)
    trajectory = _rest_trajectory(mech, omega=2.0)
    # Measured: all three agree exactly here; the bounds allow a few ulps of other BLAS orders.
    assert abs(output_series(mech, trajectory, "tip_x")[0] - 1.0) < 1e-15
    # ω × B with ω = 2 ẑ, B = (1, √3, 0): (−2√3, 2, 0).
    assert abs(output_series(mech, trajectory, "tip_vx")[0] + 2 * np.sqrt(3)) < 1e-14
    assert abs(output_series(mech, trajectory, "tip_vy")[0] - 2.0) < 1e-14


def test_point_output_problems_name_the_field(load_variant):
    old = 'crank_rate = { kind = "joint_rate", joint = "O" }'
    new = (old + '\np1 = { kind = "point_position", body = "nobody", location = [0.0, 0.0, 0.0] }'
           '\np2 = { kind = "point_velocity", body = "crank" }'
           '\np3 = { kind = "point_position", body = "crank", location = [0.0, 0.0, 0.0], '
           'component = "w" }'
           '\np4 = { kind = "point_position", body = "ground", location = [0.0, 0.0, 0.0] }'
           '\np5 = { kind = "position", body = "ground" }'
           '\np6 = { kind = "point_position", body = "crank", location = [0.0, 0.0], axis = 1 }')
    problems = _problems(load_variant, "fourbar", [(old, new)])
    assert _has(problems, "outputs.p1.body", "unknown body 'nobody'")
    assert _has(problems, "outputs.p2.location", "missing required field")
    assert _has(problems, "outputs.p3.component", "expected x, y or z, got 'w'")
    assert _has(problems, "outputs.p4.body", "ground does not move")
    assert _has(problems, "outputs.p5.body", "ground does not move")
    assert _has(problems, "outputs.p6.location", "expected a list of 3 numbers")
    assert _has(problems, "outputs.p6.axis", "unknown key")


# -- slender bodies ---------------------------------------------------------------------------
BAR = np.diag([1 / 12, 0.0, 1 / 12])


def test_a_slender_bar_is_accepted_in_any_orientation():
    assert inertia_problem(BAR) is None
    turned = Rotation.from_euler("ZXZ", [30.0, 40.0, 50.0], degrees=True).as_matrix()
    assert inertia_problem(turned @ BAR @ turned.T) is None


def test_a_point_mass_inertia_is_physical():
    """All three moments zero: whether its joints hold it is checked with the joints
    (tests/model/test_parts.py)."""
    assert inertia_problem(np.zeros((3, 3))) is None


@pytest.mark.parametrize("moments, fragment", [
    ([1 / 12, -1e-3, 1 / 12], "negative principal moment"),
    ([1 / 12, 0.0, 0.0], "two zero principal moments"),
    ([1 / 12, 0.0, 1 / 6], "triangle inequality"),
    ([1.0, 1.0, 2.5], "triangle inequality"),
])
def test_unphysical_inertia_is_rejected(moments, fragment):
    assert fragment in inertia_problem(np.diag(moments))


def test_a_slender_body_loads(load_variant):
    mech = load_variant("fourbar", [("inertia = [0.0814, 26.1, 26.0496]",
                                     "inertia = [0.0, 26.1, 26.1]")])
    assert mech.bodies[mech.body_index("crank")].inertia[0, 0] == 0.0


# -- prescribed velocities --------------------------------------------------------------------
VELOCITIES = """
[[initial.velocities]]
joint = "B"
rate = 0.5

[[initial.velocities]]
body = "crank"
location = [1.0, 1.7320508075688772, 0.0]
velocity = [1.0, -2.0, 0.0]
components = ["x"]

[[initial.velocities]]
body = "coupler"
location = [1.0, 1.7320508075688772, 0.0]
velocity = [1.0, -2.0, 0.0]
"""


def test_prescribed_velocities_load(load_variant):
    mech = load_variant("fourbar", [("rate = 0.0\n", "rate = 0.0\n" + VELOCITIES)])
    joint_rate, tip, coupler = mech.initial.prescribed
    assert joint_rate == PrescribedJointRate("B", 0.5)
    assert isinstance(tip, PrescribedPointVelocity) and tip.components == (0,)
    assert np.allclose(tip.point, [1.0, 0.0, 0.0], atol=1e-15)
    assert tip.velocity.tolist() == [1.0, -2.0, 0.0]
    assert coupler.components == (0, 1)  # planar default: x and y


BAD_VELOCITIES = """
[[initial.velocities]]
joint = "O"
rate = 1.0

[[initial.velocities]]
joint = "Q"
rate = 1.0

[[initial.velocities]]
joint = "B"
body = "crank"

[[initial.velocities]]
body = "ground"
location = [0.0, 0.0, 0.0]
velocity = [0.0, 0.0, 0.0]

[[initial.velocities]]
body = "crank"
location = [0.0, 0.0, 1.0]
velocity = [0.0, 0.0, nan]
components = ["z"]

[[initial.velocities]]
joint = "C"
rate = "fast"
speed = 2
"""


def test_prescribed_velocity_problems_name_the_entry(load_variant):
    edit = ("rate = 0.0\n", "rate = 0.0\n" + BAD_VELOCITIES)
    problems = _problems(load_variant, "fourbar", [edit])
    assert _has(problems, "initial.velocities[0].joint", "is the driver")
    assert _has(problems, "initial.velocities[1].joint", "unknown joint 'Q'")
    assert _has(problems, "initial.velocities[2]", "give either joint")
    assert _has(problems, "initial.velocities[3].body", "ground does not move")
    assert _has(problems, "initial.velocities[4].location", "z = 0")
    assert _has(problems, "initial.velocities[4].velocity", "non-finite")
    assert _has(problems, "initial.velocities[4].components", "from x, y")
    assert _has(problems, "initial.velocities[5].rate", "expected a finite number")
    assert _has(problems, "initial.velocities[5].speed", "unknown key")


def test_a_spherical_joint_rate_cannot_be_prescribed(load_variant):
    entry = '\n[[initial.velocities]]\njoint = "B"\nrate = 1.0\n'
    edit = ("rate = 0.0\n", "rate = 0.0\n" + entry)
    problems = _problems(load_variant, "fourbar_spatial", [edit])
    assert _has(problems, "initial.velocities[0].joint", "spherical")


@pytest.mark.parametrize("edit", [
    TIP,
    ("rate = 0.0\n", "rate = 0.0\n" + VELOCITIES),
])
def test_content_hash_covers_new_fields(load_variant, edit):
    assert load_variant("fourbar", [edit], stem="fourbar").content_hash != SHIPPED_HASHES["fourbar"]


# -- names and limits -------------------------------------------------------------------------
def test_names_must_be_printable_and_unpadded(load_variant):
    problems = _problems(load_variant, "fourbar", [
        ('name = "crank"', 'name = "cra\\u202enk"'), ('name = "B"', 'name = "B\\u200b"'),
        ('name = "coupler"', 'name = " coupler"'),
        ('crank_rate = {', '"rate\\n" = {'),
    ])
    assert _has(problems, "bodies[0].name", "U+202E")
    assert _has(problems, "joints[1].name", "U+200B")
    assert _has(problems, "bodies[1].name", "leading or trailing whitespace")
    assert _has(problems, "outputs['rate\\n']", "U+000A")


def test_markup_and_emoji_names_load(load_variant):
    mech = load_variant("fourbar", [('"crank"', '"<script>🦀</script>"')])
    assert mech.bodies[0].name == "<script>🦀</script>"


@pytest.mark.parametrize("edit, field, fragment", [
    (("mass = 78.1", "mass = 1e308"), "bodies[0].mass", "exceeds the limit"),
    (("mass = 78.1", "mass = 1e-300"), "bodies[0].mass", "below the smallest"),
    (("location = [2.5, 0.0, 0.0]", "location = [1e101, 0.0, 0.0]"), "joints[3].location",
     "exceeds the limit"),
    (("value = -1200.0", "value = -inf"), "forces[0].value", "finite number"),
])
def test_extreme_numbers_are_refused_with_their_field(load_variant, edit, field, fragment):
    assert _has(_problems(load_variant, "fourbar", [edit]), field, fragment)


# -- joint-angle offsets ----------------------------------------------------------------------
def test_a_joint_angle_offset_is_added_to_the_angle(load_variant):
    old = 'crank_rate = { kind = "joint_rate", joint = "O" }'
    mech = load_variant("fourbar", [(old, old + '\nbeta = { kind = "joint_angle", joint = "O", '
                                               'offset = -0.25 }')])
    trajectory = _rest_trajectory(mech, omega=2.0)
    assert mech.output("beta").offset == -0.25
    assert output_series(mech, trajectory, "beta")[0] == -0.25


def test_offset_problems_name_the_field(load_variant):
    old = 'crank_rate = { kind = "joint_rate", joint = "O" }'
    new = (old + '\nb1 = { kind = "joint_rate", joint = "O", offset = 1.0 }'
           '\nb2 = { kind = "joint_angle", joint = "O", offset = "pi" }')
    problems = _problems(load_variant, "fourbar", [(old, new)])
    assert _has(problems, "outputs.b1.offset", "only joint_angle outputs take an offset")
    assert _has(problems, "outputs.b2.offset", "expected a finite number")
