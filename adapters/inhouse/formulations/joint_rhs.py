"""The joint-coordinate right-hand side in one compiled call: the tree pass, the absolute mass
matrix and forces, the cut joints' Φ_q and γ, the reduction by B and the range-space solve
(the equations of :mod:`.joint_coordinates`: Arczewski 1995, eq. 2–3; Rouvinen 2003, eq. 77
and, for Baumgarte's terms, eq. 110).

Each piece is a call of its own compiled kernel (:func:`~..bodies.tree_pass.tree_pass`,
:func:`~.mass_and_forces.mass_and_forces_kernel`, :func:`~..bodies.kernels.jacobian`,
:func:`~..bodies.kernels.gamma`, :func:`~..bodies.kernels.phi`,
:func:`~.dynamics.augmented_mass_acceleration`), none inlined here: the constraint kernels are
marked :func:`~..numerics.inlining.called_from_python` and this module's entries are too, so
numba compiles their helpers once, not again inside these functions
(:mod:`~..numerics.inlining`).  The products with B are plain loops in the order of the dense
products they replace (M_θ = (BᵀM)B, Q_θ = Bᵀ(Q − M Ḃθ̇), C_θ = Φ_cut,q B, γ_θ = γ_cut −
Φ_cut,q Ḃθ̇): the Python assembly's numbers to round-off.

Arguments shared by the entries: θ, θ̇ (n_θ,); t (s); ``tree`` the tree pass's table
(:func:`~..bodies.tree_pass.tree_table`); ``dynamics`` the arguments after (q, v) of
:func:`~.mass_and_forces.mass_and_forces_kernel`; ``closure`` the cut joints'
:attr:`~..bodies.constraints.ConstraintSystem.kernel_args` and ``m_c`` its number of joint
equations (0: an open chain, whose table is then an empty system's); ``gains`` Baumgarte's
(α, β) in 1/s (zero: plain γ_θ).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from mbh._adapters.inhouse.bodies import kernels
from mbh._adapters.inhouse.bodies.tree_pass import tree_pass
from mbh._adapters.inhouse.formulations.dynamics import augmented_mass_acceleration
from mbh._adapters.inhouse.formulations.mass_and_forces import mass_and_forces_kernel
from mbh._adapters.inhouse.numerics.inlining import called_from_python


@called_from_python
@njit(cache=True)
def reduced_kernel(theta, rate, t, tree, dynamics, closure, m_c, gains):
    """(M_θ (n_θ, n_θ), Q_θ (n_θ,), C_θ (m_c, n_θ), γ_θ (m_c,)): kg·m², kg or mixed per
    coordinate; N·m or N; 1 or m per coordinate; 1/s² or m/s², the Baumgarte terms included."""
    q, b, bias = tree_pass(theta, rate, tree)
    size, n = b.shape
    v = np.zeros(size)
    for i in range(size):
        for j in range(n):
            v[i] += b[i, j] * rate[j]
    mass, force = mass_and_forces_kernel(q, v, *dynamics)
    left = np.zeros((n, size))  # BᵀM
    for j in range(n):
        for k in range(size):
            for i in range(size):
                left[j, k] += b[i, j] * mass[i, k]
    mass_theta = np.zeros((n, n))
    for j in range(n):
        for c in range(n):
            for k in range(size):
                mass_theta[j, c] += left[j, k] * b[k, c]
    loaded = force.copy()  # Q − M Ḃθ̇
    for i in range(size):
        inertial = 0.0
        for k in range(size):
            inertial += mass[i, k] * bias[k]
        loaded[i] -= inertial
    force_theta = np.zeros(n)
    for j in range(n):
        for i in range(size):
            force_theta[j] += b[i, j] * loaded[i]
    c = np.zeros((m_c, n))
    gamma = np.zeros(m_c)
    if m_c == 0:
        return mass_theta, force_theta, c, gamma
    jac = kernels.jacobian(q, t, closure)
    cut_gamma = kernels.gamma(q, v, t, closure)
    for r in range(m_c):
        along = 0.0
        for k in range(size):
            along += jac[r, k] * bias[k]
            for j in range(n):
                c[r, j] += jac[r, k] * b[k, j]
        gamma[r] = cut_gamma[r] - along
    alpha, beta = gains
    if alpha != 0.0 or beta != 0.0:
        phi = kernels.phi(q, t, closure)
        for r in range(m_c):
            rate_r = 0.0
            for j in range(n):
                rate_r += c[r, j] * rate[j]
            gamma[r] = gamma[r] - 2.0 * alpha * rate_r - beta * beta * phi[r]
    return mass_theta, force_theta, c, gamma


@called_from_python
@njit(cache=True)
def acceleration_kernel(theta, rate, t, tree, dynamics, closure, m_c, gains, cut, pivots):
    """θ̈ (n_θ,) of [M_θ C_θᵀ; C_θ 0] (:func:`reduced_kernel`) by the range-space solve at the
    relative singular-value ``cut`` in its M̃ form
    (:func:`~.dynamics.augmented_mass_acceleration`: M_θ of a tree is dense, so the diagonal
    branch of :func:`~.dynamics.range_space_acceleration` would only test its zeros), with the
    start's ``pivots`` of redundant closure rows (:func:`~.dynamics.range_space_pivots`; empty:
    none), in rad/s² or m/s² per coordinate."""
    mass, force, c, gamma = reduced_kernel(theta, rate, t, tree, dynamics, closure, m_c, gains)
    return augmented_mass_acceleration(mass, c, force, gamma, cut, pivots)
