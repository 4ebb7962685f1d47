"""In-house kinematics: derivatives against finite differences, assembly, rank analysis."""

from __future__ import annotations

import numpy as np
import pytest

from mbh._adapters.inhouse.bodies.constraints import ConstraintSystem, layout_of
from mbh._adapters.inhouse.bodies.kinematics import (InhouseAssemblyError, assemble, check,
                                                     rank_report)
from mbh._harness.model import scenario

SHIPPED = scenario.scenario_names()

# Variants that exercise every joint type and every kind of driver.
SPATIAL_PRISMATIC = ("slider_crank", [('type = "translational"', 'type = "prismatic"')])
TRANSLATIONAL_DRIVER = ("slider_crank", [('driver = "O"', 'driver = "P"')])
PRISMATIC_DRIVER = ("slider_crank_planar", [('driver = "O"', 'driver = "P"')])
CYLINDRICAL_DRIVER = ("fourbar_spatial", [('driver = "O"', 'driver = "C"')])
VARIANTS = {"spatial_prismatic": SPATIAL_PRISMATIC, "translational_driver": TRANSLATIONAL_DRIVER,
            "prismatic_driver": PRISMATIC_DRIVER, "cylindrical_driver": CYLINDRICAL_DRIVER}


@pytest.fixture(params=SHIPPED + list(VARIANTS))
def mechanism(request, load_variant):
    if request.param in VARIANTS:
        name, edits = VARIANTS[request.param]
        return load_variant(name, edits, stem=request.param)
    return scenario.load(request.param)


def random_state(mech, rng):
    """A random, unassembled (q, v); Euler parameters deliberately not normalised."""
    n = layout_of(mech).n
    return rng.normal(size=n), rng.normal(size=n)


def central_difference(function, x, h):
    columns = []
    for k in range(x.size):
        step = np.zeros_like(x)
        step[k] = h
        columns.append((function(x + step) - function(x - step)) / (2 * h))
    return np.column_stack(columns)


def test_jacobian_matches_finite_differences(mechanism):
    rng = np.random.default_rng(1)
    system = ConstraintSystem(mechanism, with_driver=True, drive=(0.3, 1.7))
    for _ in range(5):
        q, _ = random_state(mechanism, rng)
        t = rng.uniform(0, 2)
        numeric = central_difference(lambda x, t=t: system.phi(x, t), q, 1e-6)
        analytic = system.jacobian(q, t)
        # Central differences with h = 1e-6: measured max error 3.0e-10 relative to max |Φ_q|
        # over the shipped scenarios (a wrong derivative gives O(1) errors).
        np.testing.assert_allclose(analytic, numeric, atol=1e-7 * max(1.0, np.abs(analytic).max()))


def test_phi_t_matches_finite_differences(mechanism):
    rng = np.random.default_rng(2)
    system = ConstraintSystem(mechanism, with_driver=True, drive=(0.3, 1.7))
    q, _ = random_state(mechanism, rng)
    h = 1e-6
    numeric = (system.phi(q, 0.4 + h) - system.phi(q, 0.4 - h)) / (2 * h)
    np.testing.assert_allclose(system.phi_t(q, 0.4), numeric, atol=1e-7)  # measured 5.6e-10


def test_gamma_matches_second_derivative_along_a_straight_motion(mechanism):
    """Along q(s) = q + s·v, t = t0 + s (q̈ = 0): d²Φ/ds² = −γ (Frączek & Wojtyra 2009, eq. 1.16)."""
    rng = np.random.default_rng(3)
    system = ConstraintSystem(mechanism, with_driver=True, drive=(0.3, 1.7))
    for _ in range(5):
        q, v = random_state(mechanism, rng)
        t, h = 0.7, 1e-4
        second = (system.phi(q + h * v, t + h) - 2 * system.phi(q, t)
                  + system.phi(q - h * v, t - h)) / h**2
        gamma = system.gamma(q, v, t)
        # O(h²) truncation plus ~1e-16/h² round-off: measured max error 7.4e-8 relative to max |γ|.
        np.testing.assert_allclose(-second, gamma, atol=1e-5 * max(1.0, np.abs(gamma).max()))


@pytest.mark.parametrize("name", SHIPPED)
def test_assembly_residual_and_mobility(name):
    result = check(scenario.load(name))
    assert result["assembly_residual"] <= 1e-12
    assert result["mobility"] == 1
    # Grübler 0, one redundant row: tests/references/test_bricard.py
    overconstrained = {"bricard": (0, 1)}
    assert (result["grubler_mobility"], result["redundant_equations"]) \
        == overconstrained.get(name, (1, 0))


def test_assembly_from_a_perturbed_guess_reaches_machine_precision(load_variant):
    mech = load_variant("fourbar", [("[initial]\n", "[initial]\nguess = { coupler = [2.9, 2.4, 0.0] }\n")])
    assembly = assemble(mech)
    assert assembly.iterations >= 1  # positions enter Φ linearly at exact angles: one step
    assert assembly.residual <= 1e-12


def test_planar_and_spatial_fourbar_assemble_to_the_same_positions():
    planar = assemble(scenario.load("fourbar"), value=0.4)
    spatial = assemble(scenario.load("fourbar_spatial"), value=0.4)
    xy_planar = planar.q.reshape(3, 3)[:, :2]
    xy_spatial = spatial.q.reshape(3, 7)[:, :2]
    assert np.abs(xy_planar - xy_spatial).max() <= 1e-12
    assert np.abs(spatial.q.reshape(3, 7)[:, 2]).max() <= 1e-12


def test_driver_rate_gives_consistent_velocities_and_accelerations():
    mech = scenario.load("fourbar_spatial")
    assembly = assemble(mech, value=0.2, rate=1.5)
    joints = ConstraintSystem(mech)
    assert np.abs(joints.jacobian(assembly.q) @ assembly.v).max() <= 1e-12
    assert np.abs(joints.jacobian(assembly.q) @ assembly.a
                  - joints.gamma(assembly.q, assembly.v)).max() <= 1e-10


ALL_REVOLUTE = [
    ('type = "spherical"', 'type = "revolute"'),
    ('location = [1.0, 1.7320508075688772, 0.0]\n',
     'location = [1.0, 1.7320508075688772, 0.0]\naxis = [0.0, 0.0, 1.0]\n'),
    ('type = "cylindrical"', 'type = "revolute"'),
]


def test_all_revolute_spatial_fourbar_is_overconstrained(load_variant):
    mech = load_variant("fourbar_spatial", ALL_REVOLUTE, stem="fourbar_all_revolute")
    result = check(mech)
    assert result["grubler_mobility"] == -2
    assert result["mobility"] == 1
    assert result["redundant_equations"] == 3
    assert result["n_equations"] == 23 and result["rank"] == 20


PARALLELOGRAM = """
kind = "planar"
plane = "xy"
duration = 1.0
gravity = [0.0, -9.81, 0.0]
[[bodies]]
name = "crank"
mass = 1.0
inertia = [0.01, 0.1, 0.1]
position = [0.5, 0.0, 0.0]
[[bodies]]
name = "coupler"
mass = 2.0
inertia = [0.01, 0.7, 0.7]
position = [2.0, 0.0, 0.0]
[[bodies]]
name = "rocker"
mass = 1.0
inertia = [0.01, 0.1, 0.1]
position = [2.5, 0.0, 0.0]
[[joints]]
name = "O"
type = "revolute"
body1 = "ground"
body2 = "crank"
location = [0.0, 0.0, 0.0]
[[joints]]
name = "B"
type = "revolute"
body1 = "crank"
body2 = "coupler"
location = [1.0, 0.0, 0.0]
[[joints]]
name = "C"
type = "revolute"
body1 = "coupler"
body2 = "rocker"
location = [3.0, 0.0, 0.0]
[[joints]]
name = "R"
type = "revolute"
body1 = "rocker"
body2 = "ground"
location = [2.0, 0.0, 0.0]
[initial]
driver = "O"
value = VALUE
"""


def test_parallelogram_loses_rank_when_flattened(write_scenario):
    flat = scenario.load(write_scenario("parallelogram_flat", PARALLELOGRAM.replace("VALUE", "0.0")))
    raised = scenario.load(write_scenario("parallelogram", PARALLELOGRAM.replace("VALUE", "1.0")))
    flat_report = rank_report(flat, assemble(flat).q)
    raised_report = rank_report(raised, assemble(raised).q)
    assert raised_report.rank == 8 and raised_report.mobility == 1
    assert flat_report.rank == 7 and flat_report.mobility == 2
    assert raised_report.smallest_singular_value > 0.1
    assert flat_report.smallest_singular_value < 1e-12


def test_a_link_too_short_to_close_the_loop_is_reported(load_variant):
    # The rocker's own pivot moved to 1 m from C: |B − R| = 2.29 m < coupler − rocker = 3 m.
    mech = load_variant("fourbar", [
        ('location = [2.5, 0.0, 0.0]',
         'location = [4.110282120429277, 2.531203566018702, 0.0]\nlocation2 = [2.5, 0.0, 0.0]')],
        stem="fourbar_short_rocker")
    with pytest.raises(InhouseAssemblyError) as error:
        assemble(mech)
    message = str(error.value)
    assert "fourbar_short_rocker.toml" in message
    assert "cannot be assembled" in message and "max |Φ|" in message
