"""The project's acceptance tests, written as a user of the pytest plugin writes them.

Only the documented API is used: the ``mbh_runner`` and ``mbh_tolerances`` fixtures,
``campaign_params`` and the assertion helpers of ``mbh.testing``.  The cases are the acceptance
campaign beside this file (every engine's ``best`` on the four verified scenes, every
``default`` on the planar four-bar and slider-crank with its known failure); the tolerances, each
with its measured value and margin, are in ``tolerances.toml`` beside this file.  About 10 s.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from mbh.testing import (assert_convergence_order, assert_within_tolerance, campaign_params,
                         case_spec)

CAMPAIGN = Path(__file__).with_name("acceptance.toml")

#: (adapter, method, step sizes in s) of the convergence-order tests on the four-bar over 1 s;
#: the order bands are the tolerance file's ``order`` entries.  Fourth-order methods use steps
#: where their error is well above the reference's ~1e-10 rad; second- and first-order engines
#: steps where they are in their asymptotic range (measured orders in tolerances.toml).
CONVERGENCE = [
    ("inhouse", "rk4+direct", (1e-2, 5e-3, 2e-3)),
    ("pinocchio", "best", (1e-2, 5e-3, 2e-3)),
    ("mujoco", "best", (1e-3, 5e-4, 2e-4)),
    ("exudyn", "best", (1e-3, 5e-4, 2e-4)),
    ("pybullet", "best", (1e-3, 5e-4, 2e-4)),
]
CONVERGENCE_T_END = 1.0


@pytest.mark.parametrize("case", campaign_params(CAMPAIGN))
def test_case_within_its_tolerances(case, mbh_runner, mbh_tolerances):
    assert_within_tolerance(mbh_runner.run(case), mbh_tolerances.for_case(case))


@pytest.mark.parametrize("adapter,method,dts", CONVERGENCE,
                         ids=[f"fourbar-{a}-{m}" for a, m, _ in CONVERGENCE])
def test_convergence_order(adapter, method, dts, mbh_runner, mbh_tolerances):
    low, high = mbh_tolerances.for_case(case_spec("fourbar", adapter, method, dts[0])).order
    results = mbh_runner.steps("fourbar", adapter, method, dts, t_end=CONVERGENCE_T_END)
    assert_convergence_order(results, low, high)
