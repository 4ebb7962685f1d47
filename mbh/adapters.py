"""The adapter contract: everything a solver's adapter imports, in one module.

Subclass :class:`Adapter` and :class:`Stepper`; build your engine's model from the
:class:`Mechanism` you receive; start it at :func:`initial_state`; report :class:`BodyStates` at
the times of the :class:`RunGrid`; raise :class:`UnsupportedCase` for what your engine cannot model
and :class:`RunFailure` when a run breaks down.  Register the adapter by an entry point in the
``mbh.adapters`` group, or pass the class or an instance to :func:`mbh.run_case` directly.
docs/adapter-contract.md is the guide, with a complete package.

Every other module of the ``mbh`` package is private and may change between releases.

Examples
--------
>>> from mbh.adapters import Adapter, MethodSpec
>>> issubclass(Adapter, object) and MethodSpec.__name__
'MethodSpec'
"""

from mbh._adapters import adapter_names, get_adapter
from mbh._adapters.base import (Adapter, MethodSpec, RunFailure, RunGrid, Stepper,
                                UnsupportedCase)
from mbh._harness.model.mechanism import (GROUND, Body, BodyForce, BodyTorque, Joint,
                                          JointActuation, Mechanism, SpringDamper)
from mbh._harness.model.topology import SpanningTree, SystemGraph, spanning_tree, system_graph
from mbh._harness.model.trajectory import BodyStates
from mbh._harness.neutral.start import initial_state

__all__ = ["GROUND", "Adapter", "Body", "BodyForce", "BodyStates", "BodyTorque", "Joint",
           "JointActuation", "Mechanism", "MethodSpec", "RunFailure", "RunGrid", "SpanningTree",
           "SpringDamper", "Stepper", "SystemGraph", "UnsupportedCase", "adapter_names",
           "get_adapter", "initial_state", "spanning_tree", "system_graph"]
