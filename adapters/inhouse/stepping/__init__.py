"""Tier 5 of the in-house formulation: the steppers and their compiled loops (one-step and
multistep), the method driver, and compilation on demand.  Imports every tier below; the adapter
(:mod:`mbh._adapters.inhouse.adapter`) sits on top.
"""
