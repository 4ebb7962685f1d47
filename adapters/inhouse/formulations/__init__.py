"""Tier 3 of the in-house formulation: the equations of motion with Lagrange multipliers and their
treatments (Baumgarte, penalty, augmented Lagrangian, projections, coordinate partitioning, placed
passages through singular positions, the DAE residual, Newton–Euler).  Imports the numerics and
bodies tiers.
"""
