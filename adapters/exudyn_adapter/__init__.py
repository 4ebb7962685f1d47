"""Exudyn adapter: the scenario in redundant absolute coordinates, solved by Exudyn's implicit
second-order integrators at fixed steps.

Like the in-house formulation, Exudyn needs no spanning tree: every body is a node with its own
coordinates and every scenario joint becomes one Exudyn constraint.

Modules: :mod:`.methods` (method parameters, their checks and Exudyn's simulation settings),
:mod:`.state` (body states ↔ Exudyn node coordinates), :mod:`.system` (the Exudyn system of one
run: built from the mechanism, solved, read back), :mod:`.adapter` (the adapter: build check,
methods, simulate).
"""

from mbh._adapters.exudyn_adapter.adapter import ExudynAdapter, ExudynModel
from mbh._adapters.exudyn_adapter.system import ExudynSystem

__all__ = ["ExudynAdapter", "ExudynModel", "ExudynSystem"]
