"""Generated scenario families (``harness/model/families.py``): the N-four-bar ``n_fourbar@N``.

The outside check is the one-degree-of-freedom model of the parallelogram branch, written here for
any N (unit bars, m = 1 kg, L = 1 m, crank angle φ from +x): N + 1 cranks turn about their ground
pivots, T = (N + 1) · ½ (mL²/3) φ̇², and N couplers translate with the crank tips,
T = N · ½ m L² φ̇²; crank centres sit at height ½ sin φ, couplers at sin φ, so

    ((N + 1)/3 + N) φ̈ = −g ((N + 1)/2 + N) cos φ,

with the first crank's tip at (cos φ, sin φ); N = 2 gives 3 φ̈ = −3.5 g cos φ
(``tests/references/test_double_fourbar.py``).
"""

from __future__ import annotations

import dataclasses
import tomllib

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from mbh._harness.model import scenario
from mbh._harness.references.routes import full_route
from mbh._harness.model.families import FAMILY_MEMBERS, FamilyError, family_document, family_names
from mbh._harness.model.outputs import output_series
from mbh._harness.references.build import AGREEMENT_LIMIT, BRANCH_ROUTE_A, reference_info, \
    reference_trajectory
from mbh._harness.model.scenario import ScenarioError

GRAVITY = 9.81
#: Fields that name or describe a scene rather than its mechanics.
_DESCRIPTIVE = {"name", "notes", "source", "content_hash", "tags"}


def one_dof_tip(n: int, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """First crank's tip (x, y), m, shape (len(times),) each, of the N-four-bar's branch model."""
    ratio = GRAVITY * ((n + 1) / 2 + n) / ((n + 1) / 3 + n)

    def rhs(_t, state):
        return [state[1], -ratio * np.cos(state[0])]

    solution = solve_ivp(rhs, (0.0, times[-1]), [np.pi / 2, -1.0], method="DOP853",
                         rtol=1e-13, atol=1e-13, t_eval=times)
    return np.cos(solution.y[0]), np.sin(solution.y[0])


def assert_same(generated, shipped, path: str) -> None:
    """Field-by-field equality of two model objects (dataclasses, tuples, dicts, arrays)."""
    if dataclasses.is_dataclass(shipped):
        assert type(generated) is type(shipped), path
        for field in dataclasses.fields(shipped):
            assert_same(getattr(generated, field.name), getattr(shipped, field.name),
                        f"{path}.{field.name}")
    elif isinstance(shipped, (tuple, list)):
        assert len(generated) == len(shipped), path
        for index, (a, b) in enumerate(zip(generated, shipped)):
            assert_same(a, b, f"{path}[{index}]")
    elif isinstance(shipped, dict):
        assert generated.keys() == shipped.keys(), path
        for key in shipped:
            assert_same(generated[key], shipped[key], f"{path}.{key}")
    elif isinstance(shipped, np.ndarray):
        np.testing.assert_array_equal(generated, shipped, err_msg=path)
    else:
        assert generated == shipped, path


def test_member_two_is_the_shipped_double_fourbar():
    generated = scenario.load("n_fourbar@2")
    shipped = scenario.load("double_fourbar")
    assert generated.name == "n_fourbar@2"
    for field in dataclasses.fields(shipped):
        if field.name not in _DESCRIPTIVE:
            assert_same(getattr(generated, field.name), getattr(shipped, field.name), field.name)


@pytest.mark.parametrize("n", FAMILY_MEMBERS["n_fourbar"])
def test_members_have_the_n_four_bar_topology(n):
    mech = scenario.load(f"n_fourbar@{n}")
    assert [b.name for b in mech.bodies][:3] == ["crank1", "coupler1", "crank2"]
    assert len(mech.bodies) == 2 * n + 1
    assert [j.name for j in mech.joints][: n + 1] == [f"O{k}" for k in range(1, n + 2)]
    assert len(mech.joints) == 3 * n + 1
    assert mech.branch == tuple(("O1", f"O{k}") for k in range(2, n + 2))
    assert mech.neutral_routes
    assert scenario.is_scenario_name(f"n_fourbar@{n}")


def test_document_is_plain_toml_data():
    """What tomllib could return: only tables, arrays, strings, floats, ints (no tuples, numpy)."""
    def check(value, path):
        if isinstance(value, dict):
            for key, item in value.items():
                assert isinstance(key, str), path
                check(item, f"{path}.{key}")
        elif isinstance(value, list):
            for index, item in enumerate(value):
                check(item, f"{path}[{index}]")
        else:
            assert type(value) in (str, float, int, bool), f"{path}: {type(value).__name__}"

    document = family_document("n_fourbar", "3")
    check(document, "n_fourbar@3")
    assert document["name"] == "n_fourbar@3"
    assert tomllib.loads('name = "n_fourbar@3"')["name"] == document["name"]


@pytest.mark.parametrize("family, parameter, message", [
    ("n_fivebar", "2", r"unknown family 'n_fivebar' \(known: n_fourbar\)"),
    ("n_fourbar", "two", "'two' is not an integer"),
    ("n_fourbar", "04", "'04' is not an integer"),
    ("n_fourbar", "", "'' is not an integer"),
    ("n_fourbar", "-1", "'-1' is not an integer"),
    ("n_fourbar", "0", "N = 0 is outside 1 … 256"),
    ("n_fourbar", "257", "N = 257 is outside 1 … 256"),
])
def test_bad_members_are_refused_naming_family_and_problem(family, parameter, message):
    with pytest.raises(FamilyError, match=message):
        family_document(family, parameter)
    with pytest.raises(ScenarioError, match=f"harness/model/families.py: {family}@{parameter}: -: "):
        scenario.load(f"{family}@{parameter}")


def test_family_listing_and_scene_listing_are_separate():
    assert family_names() == ["n_fourbar"]
    assert not any("@" in name for name in scenario.scenario_names())
    assert not scenario.is_scenario_name("n_fivebar@2")


@pytest.mark.parametrize("n", [1, 4])
def test_a_short_run_follows_the_one_dof_model(n):
    """The neutral full route over the first flattened passage (t ≈ 0.7 s) for N = 1 and 4."""
    mech = dataclasses.replace(scenario.load(f"n_fourbar@{n}"), duration=0.8)
    grid = np.arange(81) * 0.01
    run = full_route(mech, grid)
    x, y = one_dof_tip(n, grid)
    error = np.hypot(output_series(mech, run, "tip_x") - x, output_series(mech, run, "tip_y") - y)
    # Measured: 8.1e-13 m (N = 1) and 1.2e-12 m (N = 4) over 0.8 s; bound 1e-10 m.  Leaving the
    # parallelogram branch at the passage costs > 1e-4 m.
    assert error.max() <= 1e-10


def test_shipped_reference_of_member_four_matches_the_one_dof_model():
    mech = scenario.load("n_fourbar@4")
    info = reference_info(mech)
    assert info["route_a"] == list(BRANCH_ROUTE_A)
    assert info["agreement"]["max"] <= AGREEMENT_LIMIT
    run = reference_trajectory(mech)
    x, y = one_dof_tip(4, run.times)
    error = np.hypot(output_series(mech, run, "tip_x") - x, output_series(mech, run, "tip_y") - y)
    # Measured: 2.0e-11 m over the 10 s (routes agree to 4.8e-10 m, joint violation 9.2e-15 m);
    # bound 2e-10 m, 10× the measured value.
    assert error.max() <= 2e-10
