"""Every engine's ``best`` on overconstrained and flat-bodied loops names the engine's limit where
it is far from the best engine (issue "Trust 3", part 2; docs/measurements.md, "Engine settings on
hard loops"; the whole table: benchmarks/hard_loops.py).

A row names a limit by a note (or, for a failed run, a reason) that starts ``engine limit:``.
Numbers measured 2026-11-29 at dt = 1e-3 s (pinocchio 3.x, mujoco 3.x, exudyn 1.13.6 as pinned in
constraints.txt), main output's error (rad): Bennett's 4R over 1 s in-house 6.1e-13, MuJoCo
1.2e-9, Pinocchio 6.8e-7 (1.1e6×; 2718 of 4000 proximal solves unconverged, largest relative
residual 128), Exudyn failed at 0.85 s; the parallel-revolute four-bar in-house 6.0e-10,
Pinocchio 5.3e-10 (largest residual 1.8e-5: no note), MuJoCo 2.9e-7, Exudyn 2.0e-5.  Each case
runs in about a second on a warm machine (the references are cached after their first build,
~2 s each).
"""

from __future__ import annotations

import pytest

import mbh
from mbh._adapters.pinocchio_adapter.dynamics import UNCONVERGED_RESIDUAL
from tests.helpers import bennett_linkage, parallel_revolute_fourbar

LIMIT = "engine limit:"
DT = 1e-3


def _limits(result) -> list[str]:
    """The notes of a case that name an engine's limit."""
    return [note for note in result.trajectory.notes if note.startswith(LIMIT)]


def _error(mech, result) -> float:
    return result.metrics["output_errors"][mech.outputs[0].name]


@pytest.fixture(scope="module")
def bennett():
    return bennett_linkage()


@pytest.fixture(scope="module")
def fourbar_4r():
    return parallel_revolute_fourbar()


@pytest.mark.parametrize("name, t_end", [("bennett", 1.0), ("bricard", 0.5)])
def test_pinocchio_names_its_unconverged_proximal_solves(name, t_end, bennett):
    """On a spatial overconstrained loop Pinocchio's row carries the count of unconverged
    proximal solves and their largest residual, measured in the run (Bennett 2718 of 4000,
    largest 128; Bricard over 0.5 s: 1187 of 2000, largest 10.1)."""
    mech = bennett if name == "bennett" else mbh.load_scenario("bricard")
    result = mbh.run_case(mech, "pinocchio", "best", dt=DT, t_end=t_end)
    assert result.status == "ok", result.reason
    counters = result.trajectory.counters
    # bounds: a quarter of the calls (measured 0.68 on Bennett, 0.59 on Bricard) and a residual
    # 100× the threshold (measured 1.3e4× on Bennett, 1.0e3× on Bricard)
    assert counters["unconverged_solves"] >= counters["constraint_dynamics_calls"] / 4
    assert counters["max_relative_residual"] >= 100 * UNCONVERGED_RESIDUAL
    (note,) = _limits(result)
    assert note.startswith(f"{LIMIT} {counters['unconverged_solves']} of "
                           f"{counters['constraint_dynamics_calls']} pin.constraintDynamics "
                           f"solves ended unconverged")
    assert f"largest {counters['max_relative_residual']:.3g}" in note


def test_pinocchio_within_ten_times_on_parallel_revolutes_says_nothing(fourbar_4r):
    """The four-bar of parallel revolutes drawn in space keeps its redundancy off the manifold:
    Pinocchio is within 10× of the in-house formulation (measured 5.3e-10 against 6.0e-10 rad)
    and its row names no limit (largest residual measured 1.8e-5, 550× under the threshold)."""
    pinocchio = mbh.run_case(fourbar_4r, "pinocchio", "best", dt=DT, t_end=1.0)
    inhouse = mbh.run_case(fourbar_4r, "inhouse", "best", dt=DT, t_end=1.0)
    assert pinocchio.status == inhouse.status == "ok"
    assert _error(fourbar_4r, pinocchio) <= 10 * _error(fourbar_4r, inhouse)
    assert pinocchio.trajectory.counters["unconverged_solves"] == 0
    assert _limits(pinocchio) == []


def test_mujoco_counts_the_mechanisms_redundant_equations_and_names_its_softness(bennett):
    """MuJoCo's notes count Bennett's redundant rows by the rank of its equality rows (two
    connects, 6 rows, rank 2: 3 of the mechanism, 1 of the closure model) and name the soft
    constraints with the largest equality residual of the run (measured 5.5e-9 m at the
    samples, where the harness measures joint gaps up to 3.4e-9 m; 2.2× on the four-bar)."""
    result = mbh.run_case(bennett, "mujoco", "best", dt=DT, t_end=1.0)
    assert result.status == "ok", result.reason
    assert ("4 redundant closure equation(s) of 6 (rank 2 at the start): 3 of the mechanism, "
            "1 of the closure model") in result.trajectory.notes
    (note,) = _limits(result)
    assert "solref (0.002, 1)" in note  # 2·dt
    residual = float(note.split("largest equality residual at the samples ")[1].split(" m")[0])
    assert 0.0 < residual <= 3 * result.metrics["max_constraint_violation"]


def test_mujoco_error_floor_is_the_constraint_time_constant(fourbar_4r):
    """The named limit, measured: at dt = 1e-4 s with the time constant of the 1e-3 s run
    (0.002 s) MuJoCo's error stays (measured 2.9e-7 → 1.2e-7 rad), with its own 2·dt it falls
    100× (2.8e-9 rad): the softness, not RK4, sets the error."""
    coarse = mbh.run_case(fourbar_4r, "mujoco", "best", dt=DT, t_end=1.0)
    held = mbh.run_case(fourbar_4r, "mujoco", "best:solref_timeconst=0.002", dt=1e-4, t_end=1.0)
    fine = mbh.run_case(fourbar_4r, "mujoco", "best", dt=1e-4, t_end=1.0)
    assert coarse.status == held.status == fine.status == "ok"
    assert _error(fourbar_4r, held) >= _error(fourbar_4r, coarse) / 10  # measured / 2.4
    assert _error(fourbar_4r, fine) <= _error(fourbar_4r, coarse) / 30  # measured / 100


def test_exudyn_failure_on_bennett_names_newton_on_redundant_equations(bennett):
    """Exudyn's failure on Bennett (measured at 0.85 s) names the limit first, with the counts
    of its own system (23 algebraic equations on 21 coordinates: at least 3 redundant, the
    mechanism's count), and the harness's count of the joint equations follows."""
    result = mbh.run_case(bennett, "exudyn", "best", dt=DT, t_end=1.0)
    assert result.status == "failed"
    assert result.reason.startswith(f"{LIMIT} Exudyn's Newton iteration on redundant equations "
                                    f"(23 algebraic equations on 21 coordinates: at least 3 "
                                    f"redundant")
    assert "minimum step size" in result.reason
    assert result.reason.endswith("overconstrained loop: 3 of the 20 joint equations are "
                                  "redundant")


@pytest.mark.parametrize("engine, order", [("exudyn", "second order"),
                                           ("pybullet", "first order")])
def test_lower_order_engines_name_their_order(engine, order):
    """Exudyn's error falls 100× per 10× smaller step on the hard loops (measured 2.0e-5 →
    2.0e-7 rad on the parallel-revolute four-bar, 3.0e-7 → 3.0e-9 on the flat parallelogram),
    Bullet's 10× (2.0e-3 → 2.0e-4 on the R-S-R-R four-bar): every run says so, the shipped
    four-bar's too."""
    result = mbh.run_case(mbh.load_scenario("fourbar"), engine, "best", dt=DT, t_end=0.1)
    assert result.status == "ok", result.reason
    (note,) = _limits(result)
    assert order in note
