"""Tier 1 of the in-house formulation: dense and banded linear algebra and rank analysis, on
plain arrays (no mechanism).  Imports nothing of the in-house formulation.
"""
