"""Tests of the topology layer: system graph, spanning tree, path matrix (Arczewski 1995)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from mbh._harness.model.mechanism import (
    PLANAR_JOINT_CLASS,
    SPATIAL_JOINT_CLASS,
    Body,
    InitialState,
    Joint,
    Mechanism,
)
from mbh._harness.model.scenario import load, scenario_names
from mbh._harness.model.topology import (angular_velocities, incidence_matrix, spanning_tree,
                                         system_graph)


def exact_closure(joint: Joint) -> int:
    """Spatial cost: close a cut joint with exactly its own equations."""
    return SPATIAL_JOINT_CLASS[joint.type]


def planar_closure(joint: Joint) -> int:
    """Planar cost: close a cut joint with exactly its own planar equations."""
    return PLANAR_JOINT_CLASS[joint.type]


def point_closure(joint: Joint) -> int:
    """A 3-equation point (ball) constraint whatever the joint."""
    return 3


def weld_for_ball(joint: Joint) -> int:
    """An engine without a ball constraint: a spherical joint costs a 6-equation weld."""
    return 6 if joint.type == "spherical" else SPATIAL_JOINT_CLASS[joint.type]


# Incidence: columns in joint declaration order, +1 at body1 (edge leaves), −1 at body2 (enters).
# fourbar: O ground→crank, B crank→coupler, C coupler→rocker, R rocker→ground.
FOURBAR_INCIDENCE = [[+1, 0, 0, -1],   # ground
                     [-1, +1, 0, 0],   # crank
                     [0, -1, +1, 0],   # coupler
                     [0, 0, -1, +1]]   # rocker
# slider_crank: O ground→crank, A crank→rod, U rod→slider, P ground→slider.
SLIDER_CRANK_INCIDENCE = [[+1, 0, 0, +1],   # ground
                          [-1, +1, 0, 0],   # crank
                          [0, -1, +1, 0],   # rod
                          [0, 0, -1, -1]]   # slider


@pytest.mark.parametrize(("scenario", "expected"), [("fourbar", FOURBAR_INCIDENCE),
                                                    ("slider_crank", SLIDER_CRANK_INCIDENCE)])
def test_incidence_matrix(scenario, expected):
    np.testing.assert_array_equal(incidence_matrix(load(scenario)), expected)


def test_system_graph_labels_vertices_and_edges():
    graph = system_graph(load("slider_crank"))
    assert graph.vertices == ("ground", "crank", "rod", "slider")
    assert graph.edges == ("O", "A", "U", "P")
    np.testing.assert_array_equal(graph.incidence, SLIDER_CRANK_INCIDENCE)
    assert not graph.incidence.flags.writeable


# Cut B: crank on ground through O (along), rocker on ground through R (rocker→ground, run
# backwards), coupler on the rocker through C (coupler→rocker, run backwards).
FOURBAR_PATHS = [[1, 0, 0],      # O: crank, coupler, rocker
                 [0, -1, 0],     # C
                 [0, -1, -1]]    # R
# Cut A: crank through O, slider through P (along), rod on the slider through U (rod→slider,
# run backwards).
SLIDER_CRANK_PATHS = [[1, 0, 0],     # O: crank, rod, slider
                      [0, -1, 0],    # U
                      [0, 1, 1]]     # P


@pytest.mark.parametrize(("scenario", "cost", "expected"), [
    ("fourbar", planar_closure, FOURBAR_PATHS),
    ("slider_crank", exact_closure, SLIDER_CRANK_PATHS),
])
def test_path_matrix(scenario, cost, expected):
    np.testing.assert_array_equal(spanning_tree(load(scenario), cost).path_matrix(), expected)


@pytest.mark.parametrize("scenario", scenario_names())
def test_path_matrix_inverts_tree_incidence(scenario):
    # P·S_T = −I and S0_T·P = 1ᵀ: each body's path crosses exactly one edge at ground and
    # enters the body through its parent joint.
    mech = load(scenario)
    cost = planar_closure if mech.planar else exact_closure
    tree = spanning_tree(mech, cost)
    columns = [joint.name in tree.tree_joints for joint in mech.joints]
    incidence = incidence_matrix(mech)[:, columns]
    paths = tree.path_matrix()
    np.testing.assert_array_equal(paths @ incidence[1:], -np.eye(len(mech.bodies)))
    np.testing.assert_array_equal(incidence[0] @ paths, np.ones(len(mech.bodies)))


@pytest.mark.parametrize(("scenario", "cost", "cut"), [
    ("fourbar", planar_closure, ("B",)),              # equal costs: depth 2 beats O/R (depth 3)
    ("fourbar_spatial", exact_closure, ("B",)),       # spherical: 3 < 4 (C) < 5 (O, R)
    ("slider_crank", exact_closure, ("A",)),          # spherical: 3 < 4 (U) < 5 (O, P)
    ("slider_crank_planar", planar_closure, ("A",)),  # A, S tie on depth 2; A declared first
    ("fourbar_spatial", weld_for_ball, ("C",)),       # B now costs 6: cylindrical C (4) is cut
])
def test_cut_choice(scenario, cost, cut):
    assert spanning_tree(load(scenario), cost).cut_joints == cut


def test_names_break_remaining_ties_whatever_the_declaration_order():
    mech = load("fourbar")
    reversed_joints = dataclasses.replace(mech, joints=mech.joints[::-1])
    assert spanning_tree(reversed_joints, planar_closure).cut_joints == ("B",)


def test_slider_crank_tree_structure():
    tree = spanning_tree(load("slider_crank"), exact_closure)
    assert tree.tree_joints == ("O", "U", "P")
    assert tree.parent == {"crank": "ground", "rod": "slider", "slider": "ground"}
    assert tree.parent_joint == {"crank": "O", "rod": "U", "slider": "P"}
    assert tree.flipped == {"O": False, "U": True, "P": False}
    assert tree.order == ("crank", "slider", "rod")


def test_weld_cost_tree_structure():
    tree = spanning_tree(load("fourbar_spatial"), weld_for_ball)
    assert tree.parent == {"crank": "ground", "coupler": "crank", "rocker": "ground"}
    assert tree.flipped == {"O": False, "B": False, "R": True}
    assert tree.redundant_closure_equations == 0


@pytest.mark.parametrize(("scenario", "cost", "redundant"), [
    ("fourbar", point_closure, 1),          # planar revolute B (class 2) closed with 3 equations
    ("fourbar_spatial", point_closure, 0),  # spherical B (class 3) closed with 3 equations
])
def test_redundant_closure_equations(scenario, cost, redundant):
    assert spanning_tree(load(scenario), cost).redundant_closure_equations == redundant


def test_disconnected_mechanism_names_the_lost_bodies():
    mech = load("fourbar")
    without_o_b = dataclasses.replace(mech, joints=(mech.joint("C"), mech.joint("R")))
    with pytest.raises(ValueError, match="'fourbar'") as error:
        spanning_tree(without_o_b, planar_closure)
    assert "'crank'" in str(error.value)
    assert "coupler" not in str(error.value) and "rocker" not in str(error.value)


def test_closure_cost_must_be_a_count():
    with pytest.raises(ValueError, match="closure_equations\\('O'\\)"):
        spanning_tree(load("fourbar"), lambda joint: -1)


def rotation(axis: str, angle: float) -> np.ndarray:
    """Rotation matrix about the world x or z axis, shape (3, 3)."""
    c, s = np.cos(angle), np.sin(angle)
    if axis == "x":
        return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def chain(second_axis, second_reversed: bool) -> Mechanism:
    """Two links: J1 ground→link1 about z; J2 link1→link2 (reversed: link2→link1) about
    ``second_axis``, shape (3,)."""
    zero, ez = np.zeros(3), np.array([0.0, 0.0, 1.0])
    axis = np.asarray(second_axis, dtype=float)
    normal = np.cross(axis, [0.0, 1.0, 0.0])  # both test axes (x, z) are perpendicular to y
    bodies = tuple(Body(name, 1.0, np.eye(3), zero, np.eye(3)) for name in ("link1", "link2"))
    ends = ("link2", "link1") if second_reversed else ("link1", "link2")
    joints = (Joint("J1", "revolute", "ground", "link1", zero, zero, ez, ez,
                    np.array([1.0, 0.0, 0.0]), np.array([1.0, 0.0, 0.0])),
              Joint("J2", "revolute", *ends, zero, zero, axis, axis, normal, normal))
    return Mechanism(name="chain", kind="spatial", bodies=bodies, joints=joints, forces=(),
                     gravity=zero, initial=InitialState("J1", 0.0, 0.0), duration=1.0, outputs=())


def test_planar_two_link_chain():
    mech = chain([0.0, 0.0, 1.0], second_reversed=False)
    tree = spanning_tree(mech, exact_closure)
    axes = np.tile([0.0, 0.0, 1.0], (2, 1))
    np.testing.assert_array_equal(angular_velocities(mech, tree, axes, [1.0, 2.0]),
                                  [[0.0, 0.0, 1.0], [0.0, 0.0, 3.0]])


def skew_vector(matrix: np.ndarray) -> np.ndarray:
    """The vector w of a skew-symmetric matrix [w]×, shape (3,)."""
    return np.array([matrix[2, 1], matrix[0, 2], matrix[1, 0]])


@pytest.mark.parametrize("second_reversed", [False, True])
def test_spatial_chain_matches_finite_differences(second_reversed):
    # link2 = Rz(q1)·Rx(±q2): J2's angle turns body2 relative to body1, so when J2 is declared
    # link2→link1 the rate enters with the opposite sign.
    mech = chain([1.0, 0.0, 0.0], second_reversed)
    tree = spanning_tree(mech, exact_closure)
    sign = -1.0 if second_reversed else 1.0
    q0, rates = np.array([0.4, -0.9]), np.array([0.7, -1.3])

    def orientations(t):
        q1, q2 = q0 + t * rates
        return rotation("z", q1), rotation("z", q1) @ rotation("x", sign * q2)

    axes = np.array([[0.0, 0.0, 1.0], rotation("z", q0[0]) @ [1.0, 0.0, 0.0]])
    omega = angular_velocities(mech, tree, axes, rates)
    # Central differences, h = 1e-5: truncation h²/6·|R'''| ≲ 1e-10·|rate|³, round-off
    # ~ ε/h ~ 1e-11; measured error 3e-11, a sign error would show as ~1.
    h = 1e-5
    for body, (before, now, after) in enumerate(zip(orientations(-h), orientations(0.0),
                                                    orientations(h))):
        expected = skew_vector((after - before) / (2 * h) @ now.T)
        np.testing.assert_allclose(omega[body], expected, rtol=0, atol=1e-9)


def test_sliding_joints_add_no_rotation():
    # slider_crank_planar, cut A: crank on ground via O, slider via P, rod on the slider via S
    # (rod→slider, run backwards).  Axis rows and rates of P are ignored.
    mech = load("slider_crank_planar")
    tree = spanning_tree(mech, planar_closure)
    assert tree.tree_joints == ("O", "S", "P")
    axes = [[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]
    omega = angular_velocities(mech, tree, axes, [2.0, 5.0, 7.0])
    np.testing.assert_array_equal(omega, [[0.0, 0.0, 2.0], [0.0, 0.0, -5.0], [0.0, 0.0, 0.0]])


def test_angular_velocities_reject_multi_rotation_joints():
    mech = load("slider_crank")
    tree = spanning_tree(mech, exact_closure)
    with pytest.raises(ValueError, match="joint 'U'.*universal"):
        angular_velocities(mech, tree, np.zeros((3, 3)), np.zeros(3))


def test_angular_velocities_name_bad_shapes():
    mech = load("fourbar")
    tree = spanning_tree(mech, planar_closure)
    with pytest.raises(ValueError, match="joint_rates must have shape"):
        angular_velocities(mech, tree, np.zeros((3, 3)), np.zeros(4))


@pytest.mark.parametrize("name", ["fourbar", "fourbar_spatial"])
def test_angular_velocity_map_matches_inhouse_velocities(name):
    """Joint rates measured from an in-house velocity analysis, mapped through the path matrix
    (Arczewski 1995, eq. 3/7), give back the in-house absolute angular velocities."""
    from mbh._adapters.inhouse.bodies.constraints import layout_of
    from mbh._adapters.inhouse.bodies.kinematics import assemble
    from mbh._adapters.inhouse.bodies.states import body_states
    from mbh._harness.model.mechanism import SPATIAL_JOINT_CLASS
    from mbh._harness.model.outputs import body_rotations, joint_rate

    mech = load(name)
    assembly = assemble(mech, value=0.4, rate=1.7)
    states = body_states(layout_of(mech), assembly.q, assembly.v)
    rotations = body_rotations(states.quaternion)
    tree = spanning_tree(mech, lambda joint: SPATIAL_JOINT_CLASS[joint.type])
    joints = [mech.joint(j) for j in tree.tree_joints]
    axes = np.array([(np.eye(3) if j.body1 == "ground" else rotations[mech.body_index(j.body1)])
                     @ j.axis1 for j in joints])
    rates = np.array([joint_rate(mech, j, states.angular_velocity, rotations) for j in joints])
    mapped = angular_velocities(mech, tree, axes, rates)
    assert np.abs(mapped - states.angular_velocity).max() <= 1e-12
    assert np.abs(states.angular_velocity).max() > 0.5  # a moving mechanism, not a trivial match


# --- large graphs: Kruskal's maximum-cost tree instead of the enumeration --------------------

@pytest.mark.parametrize("cost", [exact_closure, planar_closure, point_closure, weld_for_ball])
@pytest.mark.parametrize("scenario", [*scenario_names(),
                                      *(f"n_fourbar@{n}" for n in (1, 2, 3, 4, 5, 6))])
def test_the_greedy_tree_is_the_exhaustive_choice(scenario, cost, monkeypatch):
    """Where both run, Kruskal's tree (forced with EXHAUSTIVE_LIMIT = 0) cuts the same joints as
    the enumeration of every spanning tree."""
    import mbh._harness.model.topology as topology

    mech = load(scenario)
    if cost is planar_closure and not mech.planar:
        pytest.skip("planar joint classes only")
    exhaustive = spanning_tree(mech, cost)
    monkeypatch.setattr(topology, "EXHAUSTIVE_LIMIT", 0)
    greedy = spanning_tree(mech, cost)
    assert greedy.cut_joints == exhaustive.cut_joints
    np.testing.assert_array_equal(greedy.path_matrix(), exhaustive.path_matrix())


def test_a_64_cell_n_fourbar_gets_a_breadth_first_tree_at_once():
    """C(193, 64) candidate cuts: only the greedy tree is possible.  A breadth-first tree of the
    N-four-bar: every crank on its ground joint (depth 1), every coupler on a crank (depth 2)."""
    tree = spanning_tree(load("n_fourbar@64"), planar_closure)
    depths = np.count_nonzero(tree.path_matrix(), axis=0)  # tree joints on each body's path
    assert len(tree.cut_joints) == 64 and depths.max() == 2
