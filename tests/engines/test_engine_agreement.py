"""The in-house formulation against Pinocchio, an independent formulation, on every scenario.

The in-house engine integrates absolute body coordinates (centre and orientation of every body,
index-1 constrained equations); the Pinocchio adapter integrates joint coordinates of a spanning
tree with the loop closures as proximal constraints.  Both run their ``best`` method (RK4 with
projection onto the constraint manifold) from the common start, so their difference is the
difference of two 4th-order integration errors plus any difference between the two formulations
of the physics.  Every quantity is compared: every named output of the scenario and every
body's centre of mass (world position, m), as the maximum over all samples of the whole run.

The difference shrinks like dt⁴ between dt = 5e-4 and 2.5e-4 s (measured order 3.81–4.19 on
every quantity below), so it is integration error, not a difference of formulation.  At
1.25e-4 s (not run by the test: 40 s of CPU) it fell further to 9.7e-12–3.0e-9 (order 3.3–4.9
from 2.5e-4 s; at most 4.5e-11 of a quantity's range), so any difference in the physics is
below that.  The check is sensitive: 1 ppm more coupler mass in the Pinocchio model only gives
2.3e-7 rad of crank angle on fourbar_spatial in the first second at 2e-3 s, 72× the measured
agreement.

Measured on 2026-11-23 with :func:`max_differences` (evaluation grid of
:func:`mbh._harness.model.timegrid.sample_times`, 10 ms).  A test allows :data:`MARGIN` × the measured
figure, and never less than :data:`ROUNDOFF` × the quantity's range over the run (a bound below
that would assert round-off, which differs between CPUs).  The two engines' own errors against
the reference are correlated (slider_crank_planar, dt = 1e-3, full run: crank angle 3.56e-5 rad
for both, against 7.1e-8 rad between them), so this agreement checks the physics, not accuracy;
accuracy is tested against the reference in ``test_engine_reference.py``.

The full-duration test is ``slow`` (about 35 s of CPU); the default suite runs the first second
at dt = 2e-3 s (about 3 s of CPU).
"""

from __future__ import annotations

import numpy as np
import pytest

from mbh._adapters import get_adapter
from mbh._harness.model import scenario
from mbh._harness.model.outputs import output_series
from mbh._harness.model.timegrid import sample_times
from mbh._harness.model.trajectory import Trajectory

ENGINES = ("inhouse", "pinocchio")
SCENARIOS = ("fourbar", "fourbar_spatial", "slider_crank", "slider_crank_planar")
#: Allowed multiple of a measured difference: a regression of half an order of magnitude fails.
MARGIN = 3.0
#: Smallest bound relative to a quantity's range over the run (cross-CPU round-off).
ROUNDOFF = 1e-12
#: Steps of the full-duration comparison, s (coarse, fine).
FULL_DTS = (5e-4, 2.5e-4)
#: Accepted order of the difference between FULL_DTS: 4 ± 0.5 (measured 3.81–4.19).
ORDER, ORDER_TOL = 4.0, 0.5
#: Step (s) and end time (s) of the short comparison in the default suite.  Over one second the
#: difference reaches a floor near 1e-12 (slider_crank_planar slider_x: 2.19e-11, 1.42e-12,
#: 8.2e-13 m at dt = 2e-3, 1e-3, 5e-4 s), so the short test uses 2e-3 s, where every figure
#: is integration error (2e-3 → 1e-3 s: order 3.9–4.3; 3.2 on fourbar_spatial's coupler and
#: rocker).
SHORT_DT, SHORT_T_END = 2e-3, 1.0

# scenario → dt → quantity → measured max |in-house − Pinocchio| over the full run.  Outputs
# in their units (joint angle rad, joint rate rad/s, position m); "com <body>": centre-of-mass
# distance, m.
FULL_RUN = {
    "fourbar": {
        5e-4: {"crank_angle": 5.82e-9, "crank_rate": 1.62e-7,
               "com crank": 5.82e-9, "com coupler": 6.69e-9, "com rocker": 6.00e-9},
        2.5e-4: {"crank_angle": 3.44e-10, "crank_rate": 9.57e-9,
                 "com crank": 3.44e-10, "com coupler": 3.95e-10, "com rocker": 3.49e-10},
    },
    "fourbar_spatial": {
        5e-4: {"crank_angle": 5.53e-9, "crank_rate": 1.59e-7,
               "com crank": 5.53e-9, "com coupler": 5.99e-9, "com rocker": 5.55e-9},
        2.5e-4: {"crank_angle": 3.80e-10, "crank_rate": 1.08e-8,
                 "com crank": 3.80e-10, "com coupler": 4.12e-10, "com rocker": 3.87e-10},
    },
    "slider_crank": {
        5e-4: {"crank_angle": 3.64e-8, "crank_rate": 1.05e-7, "slider_x": 5.20e-9,
               "com crank": 9.11e-9, "com rod": 9.22e-9, "com slider": 5.20e-9},
        2.5e-4: {"crank_angle": 2.00e-9, "crank_rate": 5.75e-9, "slider_x": 2.85e-10,
                 "com crank": 5.00e-10, "com rod": 5.06e-10, "com slider": 2.85e-10},
    },
    "slider_crank_planar": {
        5e-4: {"crank_angle": 1.22e-8, "crank_rate": 4.06e-7, "slider_x": 3.67e-9,
               "com crank": 3.04e-9, "com rod": 3.68e-9, "com slider": 3.67e-9},
        2.5e-4: {"crank_angle": 8.59e-10, "crank_rate": 2.90e-8, "slider_x": 2.61e-10,
                 "com crank": 2.15e-10, "com rod": 2.62e-10, "com slider": 2.61e-10},
    },
}

# scenario → quantity → measured max |in-house − Pinocchio| over [0, 1 s] at dt = 2e-3 s.
FIRST_SECOND = {
    "fourbar": {"crank_angle": 2.38e-9, "crank_rate": 3.28e-8,
                "com crank": 2.38e-9, "com coupler": 1.95e-8, "com rocker": 1.90e-8},
    "fourbar_spatial": {"crank_angle": 3.22e-9, "crank_rate": 4.56e-8,
                        "com crank": 3.22e-9, "com coupler": 6.51e-9, "com rocker": 6.35e-9},
    "slider_crank": {"crank_angle": 2.45e-9, "crank_rate": 1.27e-8, "slider_x": 3.64e-10,
                     "com crank": 6.13e-10, "com rod": 6.39e-10, "com slider": 3.64e-10},
    "slider_crank_planar": {"crank_angle": 2.83e-10, "crank_rate": 4.59e-9, "slider_x": 2.19e-11,
                            "com crank": 7.08e-11, "com rod": 7.27e-11, "com slider": 2.19e-11},
}


def run_best(engine: str, mech, dt: float, t_end: float) -> Trajectory:
    """``engine``'s ``best`` method on ``mech`` from 0 to ``t_end`` (s), step ``dt`` (s),
    sampled on the evaluation grid."""
    adapter = get_adapter(engine)
    return adapter.simulate(adapter.build(mech), "best", dt, t_end, sample_times(dt, t_end))


def quantities(mech, trajectory: Trajectory) -> dict[str, np.ndarray]:
    """Every named output, shape (n_samples,), and every body's centre of mass ("com <body>"),
    shape (n_samples, 3), m."""
    series = {output.name: output_series(mech, trajectory, output.name) for output in mech.outputs}
    for index, body in enumerate(mech.bodies):
        series[f"com {body.name}"] = trajectory.position[:, index]
    return series


def max_differences(name: str, dt: float, t_end: float | None = None):
    """Run both engines on scenario ``name`` and compare every quantity.

    Parameters
    ----------
    name : str
        Shipped scenario.
    dt : float
        Step, s (must divide the evaluation grid step).
    t_end : float, optional
        End time, s; the scenario's duration when omitted.

    Returns
    -------
    trajectories : dict
        Engine name → :class:`~mbh._harness.model.trajectory.Trajectory`.
    differences : dict
        Quantity → max over samples of |in-house − Pinocchio| (a centre of mass: Euclidean
        distance), in the quantity's unit.
    ranges : dict
        Quantity → its range over the in-house run (a centre of mass: largest extent of its
        coordinates), same unit.
    """
    mech = scenario.load(name)
    t_end = mech.duration if t_end is None else t_end
    trajectories = {engine: run_best(engine, mech, dt, t_end) for engine in ENGINES}
    inhouse, pinocchio = (quantities(mech, trajectories[engine]) for engine in ENGINES)
    differences, ranges = {}, {}
    for quantity, values in inhouse.items():
        gap = values - pinocchio[quantity]
        gap = np.linalg.norm(gap, axis=-1) if gap.ndim == 2 else np.abs(gap)
        differences[quantity] = float(np.max(gap))
        ranges[quantity] = float(np.max(np.ptp(values, axis=0)))
    return trajectories, differences, ranges


def check_agreement(name: str, measured: dict, differences: dict, ranges: dict,
                    trajectories: dict) -> None:
    """Both runs ended ok, every quantity was measured, each within its bound."""
    for engine, trajectory in trajectories.items():
        assert trajectory.status == "ok", f"{engine}: {trajectory.status} {trajectory.reason}"
    assert set(differences) == set(measured), f"{name}: quantities changed, re-measure"
    for quantity, difference in differences.items():
        bound = max(MARGIN * measured[quantity], ROUNDOFF * ranges[quantity])
        assert difference <= bound, f"{name} {quantity}: {difference:.3g} > {bound:.3g}"


@pytest.mark.parametrize("name", SCENARIOS)
def test_first_second_agrees_with_pinocchio(name):
    trajectories, differences, ranges = max_differences(name, SHORT_DT, SHORT_T_END)
    check_agreement(name, FIRST_SECOND[name], differences, ranges, trajectories)


@pytest.mark.slow
@pytest.mark.parametrize("name", SCENARIOS)
def test_full_duration_agrees_with_pinocchio_to_integration_error(name):
    differences = {}
    for dt in FULL_DTS:
        trajectories, differences[dt], ranges = max_differences(name, dt)
        check_agreement(name, FULL_RUN[name][dt], differences[dt], ranges, trajectories)
    coarse_dt, fine_dt = FULL_DTS
    for quantity, coarse in differences[coarse_dt].items():
        order = np.log(coarse / differences[fine_dt][quantity]) / np.log(coarse_dt / fine_dt)
        assert abs(order - ORDER) <= ORDER_TOL, f"{name} {quantity}: order {order:.2f}"
