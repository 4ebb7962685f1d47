"""Tier 4 of the in-house formulation: straight-line code generated from the kernels for one
mechanism (tracing, the generated functions and their store).  Imports the tiers below.
"""
