"""Placed passages of singular positions (:mod:`mbh._adapters.inhouse.formulations.fold`): the plan's arithmetic
on made-up indicator histories, and its effect on ``double_fourbar``'s ten passages."""

from __future__ import annotations

import numpy as np
import pytest
from tests.helpers import reduced_tip
from tests.helpers import PATH_BOUND

from mbh._adapters import get_adapter
from mbh._adapters.inhouse.formulations.fold import (SAFE_INDICATOR, passage_placement,
                                                     passage_times, plan_passage)
from mbh._adapters.integrators import integrator_class
from mbh._harness.model import scenario
from mbh._harness.model.outputs import output_series
from mbh._harness.model.timegrid import sample_times

RK4 = passage_placement(integrator_class("rk4").tableau.c)


def test_placement_is_the_middle_of_the_widest_stage_gap():
    np.testing.assert_array_equal(RK4, [0.25, 0.25, SAFE_INDICATOR])  # stages 0, 1/2, 1/2, 1
    fraction, half_gap, _ = passage_placement(integrator_class("rk8").tableau.c)
    # DOP853's widest gap runs from c = 1/3 to 0.6 (the others are at most 0.21 wide).
    assert fraction == pytest.approx((1 / 3 + 0.6) / 2)
    assert half_gap == pytest.approx((0.6 - 1 / 3) / 2)


def test_no_passage_away_from_a_crossing():
    # ρ̂ rising, ρ̂ above the zone, or a crossing more than a step beyond the passage's start.
    assert plan_passage(1.0, 1e-3, 2.0, 0.02, 0.01, 0.05, RK4) == (0.0, 0.0)
    assert plan_passage(1.0, 1e-3, 2.0, 0.06, 0.07, 0.05, RK4) == (0.0, 0.0)
    assert plan_passage(1.0, 1e-3, 2.0, 1e-2, 1.001e-2, 0.05, RK4) == (0.0, 0.0)
    assert plan_passage(1.0, 1e-3, 2.0, 0.0, 1e-3, 0.05, RK4) == (0.0, 0.0)  # rank lost: no ρ̂


def test_a_passage_puts_the_crossing_between_the_stages():
    # ρ̂ falls by 1e-5 a step of 1e-3 s (0.01 /s): the crossing is 0.3 s ahead, no passage yet.
    assert plan_passage(0.5, 1e-3, 1.0, 3e-3, 3.01e-3, 0.05, RK4) == (0.0, 0.0)
    # ρ̂ falls by 1e-4 a step (0.1 /s), 2e-4 ahead of the crossing (2 ms): the passage that
    # keeps its stages SAFE_INDICATOR from it is H = SAFE_INDICATOR / (g/2 · 0.1 /s) = 4 ms long,
    # with the crossing at c* H = 1 ms: a lead step of 1 ms first.
    dt, rate = 1e-3, 0.1
    lead, length = plan_passage(0.5, dt, 1.0, 2e-4, 2e-4 + rate * dt, 0.05, RK4)
    assert length == pytest.approx(SAFE_INDICATOR / (0.25 * rate)) == pytest.approx(4e-3)
    assert lead + 0.25 * length == pytest.approx(2e-3)
    # 0.5 ms from the crossing there is no room for that passage: a shorter one, no lead.
    lead, length = plan_passage(0.5, dt, 1.0, 5e-5, 5e-5 + rate * dt, 0.05, RK4)
    assert (lead, length) == (0.0, pytest.approx(2e-3))


def test_a_passage_ends_by_the_next_sample():
    dt, rate = 1e-3, 1.0  # the crossing 1 ms ahead, at t = 1.000 s; H = dt
    lead, length = plan_passage(0.999, dt, 1.0005, 1e-3, 1e-3 + rate * dt, 0.05, RK4)
    # A sample 0.5 ms after the crossing: the passage ends there, H = 0.5 ms / (1 − c*).
    assert length == pytest.approx(0.5e-3 / 0.75)
    assert lead + 0.25 * length == pytest.approx(1e-3)
    assert 0.999 + lead + length == pytest.approx(1.0005)
    # 0.3 ms: H would be 0.4 ms < dt / 2, no better than a plain step.
    assert plan_passage(0.999, dt, 1.0003, 1e-3, 1e-3 + rate * dt, 0.05, RK4) == (0.0, 0.0)


def test_passage_times_end_on_the_grid():
    ends, k_end = passage_times(0.0, 1e-3, 700, 4e-4, 1.3e-3)
    np.testing.assert_allclose(ends, [0.7004, 0.7017, 0.702], rtol=1e-15)
    assert k_end == 702
    ends, k_end = passage_times(0.0, 1e-3, 700, 0.0, 2e-3)  # no lead, ends on the grid
    np.testing.assert_array_equal(ends, [702 * 1e-3])  # the grid time t0 + k·dt
    assert k_end == 702


# -- on double_fourbar ------------------------------------------------------------------------
def _tip_error(method: str, dt: float, t_end: float):
    """Largest tip distance (m) of ``double_fourbar`` from its one-degree-of-freedom model over
    [0, t_end] s, and the run."""
    mech = scenario.load("double_fourbar")
    run = get_adapter("inhouse").simulate(mech, method, dt, t_end,
                                          sample_times(dt, t_end, mech.sample_step))
    x, y = reduced_tip(run.times)
    error = np.hypot(output_series(mech, run, "tip_x") - x, output_series(mech, run, "tip_y") - y)
    return float(error.max()), run


def test_best_converges_through_the_first_two_passages():
    """``best`` over the first 1.5 s (passages at 0.71 and 1.23 s; later the crank creeps over
    the top, which amplifies any earlier error 14–33-fold before the next one).  Measured tip
    errors at dt = 1e-2, 1e-3, 1e-4, 1e-5 s: 1.24e-7, 1.21e-11, 2.73e-12, 2.26e-12 m (the last
    two at the reduced model's own accuracy, rtol 1e-13), both passages placed in each run; the
    plain grid (passage=0) gave 1.23e-7, 1.41e-11, 4.02e-11, 4.48e-11 m, worse as dt shrinks.
    Bounds ≈ 2.5–4× the measured values; the order of the first three is asserted, the last two
    are equal to round-off."""
    errors = {}
    for dt in (1e-2, 1e-3, 1e-4, 1e-5):
        errors[dt], run = _tip_error("best", dt, 1.5)
        assert run.status == "ok"
        assert run.counters["passages"] == 2
    assert errors[1e-2] <= 3e-7
    assert errors[1e-3] <= 5e-11
    assert errors[1e-4] <= 1e-11 and errors[1e-5] <= 1e-11
    assert errors[1e-2] > errors[1e-3] > errors[1e-4]


def test_partition_passes_the_first_two_crossings():
    """rk4+partition over the same 1.5 s.  Measured tip errors at dt = 1e-2, 1e-3, 1e-4 s:
    5.80e-8, 6.02e-11, 6.31e-11 m with passages (1e-5: 1.15e-10; 8.1e-11 at 1e-3 on the Python
    path), 5.81e-8, 4.29e-9, 1.13e-5 m on the plain grid (1e-5: 2.6e-6).  The floor of ~6e-11 m
    is the same at clearances 1e-3, 3e-3 and 1e-2, and 8e-10 m at the index-1 strategies' 1e-4
    (:attr:`CoordinatePartitioning.passage_clearance`).  Bounds ≈ 3–5× the measured values."""
    errors = {}
    for dt in (1e-2, 1e-3, 1e-4):
        errors[dt], run = _tip_error("rk4+partition", dt, 1.5)
        assert run.status == "ok"
        assert run.counters["passages"] >= 2
    assert errors[1e-2] <= 2e-7
    assert errors[1e-3] <= 3e-10 and errors[1e-4] <= 3e-10
    assert errors[1e-2] > errors[1e-3]


@pytest.mark.parametrize("method", ["rk4+direct", "rk8+direct", "rk4+baumgarte", "heun+none",
                                    "rk4+partition"])
def test_both_paths_place_the_same_passage(method):
    """The compiled loop and the Python path plan the passage at 0.71 s alike and take the same
    steps through it (to the bound of tests/adapters/inhouse/test_compiled_path.py)."""
    mech = scenario.load("double_fourbar")
    runs = [get_adapter("inhouse").simulate(mech, f"{method}{',' if ':' in method else ':'}"
                                            f"loop={loop}", 1e-3, 0.8,
                                            sample_times(1e-3, 0.8, mech.sample_step))
            for loop in ("python", "compiled")]
    assert [(r.status, r.steps, r.counters["passages"], r.counters["rhs_evals"])
            for r in runs] == [("ok", 800, 1, runs[0].counters["rhs_evals"])] * 2
    assert np.abs(runs[0].position - runs[1].position).max() <= PATH_BOUND
    assert np.abs(runs[0].velocity - runs[1].velocity).max() <= PATH_BOUND
