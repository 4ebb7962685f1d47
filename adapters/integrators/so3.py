"""The exponential chart of SO(3) around a body's current orientation, for Lie-group stepping.

A rotation near R₀ is written R = R₀ Exp(Θ) with Θ ∈ ℝ³ (a body-axes rotation vector).  When Θ
moves with the rate Θ̇, the body-axes angular velocity is

    ω̄ = J(Θ) Θ̇,   J(Θ) = I − α(θ) Θ̂ + β(θ) Θ̂²,   α = (1 − cos θ)/θ²,   β = (θ − sin θ)/θ³,

with θ = |Θ| and Θ̂ the cross-product matrix; J is the right Jacobian of Exp, dexp of the left-
trivialised group (F. Bullo, R. Murray, *Proportional derivative control on the Euclidean group*,
1995, eq. 11; E. Hairer, C. Lubich, G. Wanner, *Geometric Numerical Integration*, 2nd ed. 2006,
§III.4 and §IV.8).  Its inverse is dexp⁻¹, the correction of Runge–Kutta–Munthe-Kaas methods.
Differentiating ω̄ = J(Θ)Θ̇ once more gives the chart's second-order equation

    Θ̈ = J(Θ)⁻¹ (ω̄̇ − J̇ Θ̇),
    J̇ Θ̇ = −α₁ (Θ·Θ̇) Θ × Θ̇ + β Θ̇ × (Θ × Θ̇) + β₁ (Θ·Θ̇) Θ × (Θ × Θ̇),

with α₁ = α′(θ)/θ and β₁ = β′(θ)/θ.  Inside one step θ = O(h) is small, where the closed forms
cancel catastrophically; below :data:`SERIES_BELOW` the coefficients come from their Taylor series
(truncation below 1e-17 there).

Every function takes arrays of shape (k, 3), one row per body.
"""

from __future__ import annotations

from math import factorial

import numpy as np

#: θ (rad) below which α, β, α₁, β₁ are evaluated by their Taylor series.
SERIES_BELOW = 0.5
_TERMS = 9
# α = Σ (−1)^k θ^{2k}/(2k+2)!, β = Σ (−1)^k θ^{2k}/(2k+3)!; α₁, β₁ their θ-derivatives over θ.
_ALPHA = np.array([(-1) ** k / factorial(2 * k + 2) for k in range(_TERMS)])
_BETA = np.array([(-1) ** k / factorial(2 * k + 3) for k in range(_TERMS)])
_ALPHA1 = np.array([(-1) ** k * 2 * k / factorial(2 * k + 2) for k in range(1, _TERMS + 1)])
_BETA1 = np.array([(-1) ** k * 2 * k / factorial(2 * k + 3) for k in range(1, _TERMS + 1)])


def _series(coefficients: np.ndarray, theta2: np.ndarray) -> np.ndarray:
    """Σ c_k θ^{2k} by Horner's rule."""
    return np.polynomial.polynomial.polyval(theta2, coefficients)


def _coefficients(theta_vec: np.ndarray) -> tuple[np.ndarray, ...]:
    """α, β, α₁, β₁ of each row, shape (k, 1) each."""
    theta2 = np.einsum("ij,ij->i", theta_vec, theta_vec)
    small = theta2 < SERIES_BELOW ** 2
    theta = np.sqrt(np.where(small, 1.0, theta2))  # the closed forms never see θ = 0
    sin, cos = np.sin(theta), np.cos(theta)
    alpha = np.where(small, _series(_ALPHA, theta2), (1.0 - cos) / theta ** 2)
    beta = np.where(small, _series(_BETA, theta2), (theta - sin) / theta ** 3)
    alpha1 = np.where(small, _series(_ALPHA1, theta2), (theta * sin - 2.0 * (1.0 - cos)) / theta ** 4)
    beta1 = np.where(small, _series(_BETA1, theta2),
                     (3.0 * sin - theta * cos - 2.0 * theta) / theta ** 5)
    return tuple(c[:, None] for c in (alpha, beta, alpha1, beta1))


def right_jacobian(theta_vec: np.ndarray) -> np.ndarray:
    """J(Θ) of every row, shape (k, 3, 3)."""
    alpha, beta, _, _ = _coefficients(theta_vec)
    hat = _hat(theta_vec)
    return np.eye(3) - alpha[:, :, None] * hat + beta[:, :, None] * (hat @ hat)


def angular_velocity(theta_vec: np.ndarray, rate: np.ndarray) -> np.ndarray:
    """ω̄ = J(Θ) Θ̇, rad/s, shape (k, 3)."""
    alpha, beta, _, _ = _coefficients(theta_vec)
    cross = np.cross(theta_vec, rate)
    return rate - alpha * cross + beta * np.cross(theta_vec, cross)


def chart_rate(theta_vec: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """Θ̇ = J(Θ)⁻¹ ω̄ = dexp⁻¹_Θ(ω̄), shape (k, 3)."""
    return np.linalg.solve(right_jacobian(theta_vec), omega[:, :, None])[:, :, 0]


def chart_acceleration(theta_vec: np.ndarray, rate: np.ndarray,
                       angular_acceleration: np.ndarray) -> np.ndarray:
    """Θ̈ = J(Θ)⁻¹ (ω̄̇ − J̇ Θ̇) (module docstring), rad/s², shape (k, 3)."""
    _, beta, alpha1, beta1 = _coefficients(theta_vec)
    along = np.einsum("ij,ij->i", theta_vec, rate)[:, None]
    cross = np.cross(theta_vec, rate)
    jdot_rate = (-alpha1 * along * cross + beta * np.cross(rate, cross)
                 + beta1 * along * np.cross(theta_vec, cross))
    return chart_rate(theta_vec, angular_acceleration - jdot_rate)


def _hat(vectors: np.ndarray) -> np.ndarray:
    """Cross-product matrices of the rows, shape (k, 3, 3)."""
    x, y, z = vectors.T
    zero = np.zeros_like(x)
    return np.stack([np.stack([zero, -z, y], -1), np.stack([z, zero, -x], -1),
                     np.stack([-y, x, zero], -1)], -2)
