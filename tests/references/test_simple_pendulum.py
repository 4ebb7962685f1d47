"""The IFToMM simple pendulum (``scenarios/simple_pendulum.toml``: 1 kg lumped on a massless 1 m
link, released horizontal at rest, g = 9.81 m/s²) against its closed form.

With θ the angle from the downward vertical and k = sin(θ0/2), ω = √(g/L), the motion from rest
at θ0 is sin(θ/2) = k sn(K(k) − ω t, k) (Jacobi's elliptic sine; at t = 0, sn(K) = 1 gives θ0 and
cn(K) = 0 a zero rate), and θ̇ = −2kω cn dn / cos(θ/2).  scipy's ``ellipj`` and ``ellipk`` take
the parameter m = k².
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.special import ellipj, ellipk

from mbh._harness.model import scenario
from mbh._harness.model.outputs import output_series
from mbh._harness.references.build import reference_trajectory

LENGTH = 1.0
GRAVITY = 9.81
START = np.pi / 2.0
#: Measured, the shipped reference (1 ms grid, 10 s) against the closed form: angle 3.7e-13 rad,
#: rate 8.2e-13 rad/s (both growing with t like the RK4 routes' phase error), bob x 3.6e-13 m and
#: y 2.4e-13 m.  Bound: the issue's 1e-9 rad, the bound the reference was accepted on.
BOUND = 1e-9


def closed_form(times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """θ (rad) and θ̇ (rad/s) of the pendulum at ``times`` (s), shape (n,) each."""
    k = np.sin(START / 2.0)
    omega = np.sqrt(GRAVITY / LENGTH)
    sn, cn, dn, _ = ellipj(ellipk(k * k) - omega * times, k * k)
    angle = 2.0 * np.arcsin(k * sn)
    return angle, -2.0 * k * omega * cn * dn / np.cos(angle / 2.0)


@pytest.fixture(scope="module")
def pendulum():
    mech = scenario.load("simple_pendulum")
    return mech, reference_trajectory(mech)


def test_the_closed_form_starts_at_rest_from_the_horizontal():
    angle, rate = closed_form(np.array([0.0]))
    # Measured: θ(0) − θ0 = 0 exactly, θ̇(0) = −2.7e-16 rad/s (cn(K) is not exactly 0).
    assert abs(angle[0] - START) <= 1e-15 and abs(rate[0]) <= 1e-15


def test_the_reference_angle_and_rate_follow_the_closed_form(pendulum):
    mech, reference = pendulum
    assert reference.times[-1] == mech.duration == 10.0
    angle, rate = closed_form(reference.times)
    assert np.abs(output_series(mech, reference, "angle") - angle).max() <= BOUND
    assert np.abs(output_series(mech, reference, "rate") - rate).max() <= BOUND


def test_the_reference_bob_stays_on_the_closed_form_circle(pendulum):
    mech, reference = pendulum
    angle, _ = closed_form(reference.times)
    assert np.abs(output_series(mech, reference, "bob_x") - LENGTH * np.sin(angle)).max() <= BOUND
    assert np.abs(output_series(mech, reference, "bob_y") + LENGTH * np.cos(angle)).max() <= BOUND
