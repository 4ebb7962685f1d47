"""Tier 2 of the in-house formulation: absolute coordinates of the bodies (planar x, y, φ; spatial
R and Euler parameters), the constraint library as tables of primitives and its compiled kernels
(Φ, Φ_q, Φ_t, γ), conversions to body states, and kinematic analysis (assembly, velocity,
acceleration).  Imports only the numerics tier.
"""
