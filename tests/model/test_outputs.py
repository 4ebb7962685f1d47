"""Orientation arithmetic of harness/model/outputs.py that the verdict's motion check relies on."""

from __future__ import annotations

import numpy as np

from mbh._harness.model.outputs import rotation_between, wrap_angle


def _about_z(angle) -> np.ndarray:
    """Scalar-first quaternions of turns about z, shape (..., 4)."""
    half = 0.5 * np.asarray(angle, dtype=float)
    return np.stack([np.cos(half), 0 * half, 0 * half, np.sin(half)], axis=-1)


def test_the_turn_between_planar_orientations_is_their_wrapped_angle_difference():
    first = np.array([[0.0, 0.3], [-3.0, 2.0]])
    second = np.array([[0.1, 0.3], [3.0, -2.5]])
    expected = np.abs(wrap_angle(second - first))  # 0.1, 0; 2π − 6, 2π − 4.5
    turned = rotation_between(_about_z(first), _about_z(second))
    assert turned.shape == (2, 2)
    # a quaternion of unit norm holds its angle to a few ulp; 1e-12 rad allows any rounding
    assert np.abs(turned - expected).max() <= 1e-12


def test_the_turn_ignores_the_quaternion_s_sign_and_norm_and_reads_small_angles():
    start = np.array([0.5, -0.5, 0.5, 0.5])
    axis = np.array([1.0, 2.0, 2.0]) / 3.0
    small = 1e-9
    nudge = np.concatenate([[np.cos(small / 2)], np.sin(small / 2) * axis])
    # q ⊗ nudge, written out (scalar first)
    w, v = start[0], start[1:]
    moved = np.concatenate([[w * nudge[0] - v @ nudge[1:]],
                            w * nudge[1:] + nudge[0] * v + np.cross(v, nudge[1:])])
    # a product of two unit quaternions is good to a few ulp per component, so the angle to
    # ~1e-15 rad; 1e-14 allows any rounding, while a cosine-based angle (arccos of |q₁·q₂|)
    # cannot read below ~1e-8 rad
    assert rotation_between(start, -3.0 * start) <= 1e-14
    assert abs(rotation_between(start, 2.0 * moved) - small) <= 1e-14


def test_an_undefined_orientation_gives_nan_not_an_exception():
    identity = np.tile([1.0, 0.0, 0.0, 0.0], (2, 1))
    turned = rotation_between(identity, np.array([[0.0] * 4, [np.nan] * 4]))
    assert np.isnan(turned).all()
