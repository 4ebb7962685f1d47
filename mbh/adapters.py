"""The adapter contract: everything a solver's adapter imports, in one module.

Subclass :class:`Adapter` and :class:`Stepper`; build your engine's model from the
:class:`Mechanism` you receive (its parts: :class:`Body`, :class:`Joint`, the loads
:class:`BodyForce`, :class:`BodyTorque`, :class:`JointActuation`, :class:`SpringDamper`, and
:data:`GROUND`); start it at :func:`initial_state`; report :class:`BodyStates` at the times of the
:class:`RunGrid`; raise :class:`UnsupportedCase` for what your engine cannot model and
:class:`RunFailure` when a run breaks down.  A joint-coordinate engine cuts closed loops with
:func:`spanning_tree` (its closure cost :data:`UNCLOSABLE` for a joint it cannot close) over the
body graph (:func:`system_graph`).

Register the adapter by an entry point in the group :data:`ENTRY_POINT_GROUP` (``mbh.adapters``),
or pass the class or an instance to :func:`mbh.run_case` or :func:`mbh.run_campaign` without
packaging it.  :func:`adapter_names` and :func:`get_adapter` read the registry
(:class:`UnknownAdapterError`, :class:`AdapterLoadError`); :class:`AdapterChoiceError` is raised for
a class or instance that cannot stand for an adapter.  docs/adapter-contract.md is the guide, with
a complete package.

Every module of ``mbh`` but ``mbh``, ``mbh.adapters`` and ``mbh.testing`` is private and may
change between releases.

Examples
--------
>>> from mbh.adapters import Adapter, MethodSpec, Stepper
>>> sorted(Adapter.__abstractmethods__)
['_start', 'build', 'methods', 'version']
>>> sorted(Stepper.__abstractmethods__)
['_states', '_step_to']
>>> MethodSpec("best", "RK4", {"alpha": 50.0}).resolve({"alpha": "20"})
{'alpha': 20.0}
"""

from mbh._adapters import (ENTRY_POINT_GROUP, AdapterChoiceError, AdapterLoadError,
                           UnknownAdapterError, adapter_names, get_adapter)
from mbh._adapters.base import (UNCLOSABLE, Adapter, MethodSpec, RunFailure, RunGrid, Stepper,
                                UnsupportedCase)
from mbh._harness.model.mechanism import (GROUND, Body, BodyForce, BodyTorque, Joint,
                                          JointActuation, Mechanism, SpringDamper)
from mbh._harness.model.topology import SpanningTree, SystemGraph, spanning_tree, system_graph
from mbh._harness.model.trajectory import BodyStates
from mbh._harness.neutral.start import initial_state

__all__ = ["ENTRY_POINT_GROUP", "GROUND", "UNCLOSABLE", "Adapter", "AdapterChoiceError",
           "AdapterLoadError", "Body", "BodyForce", "BodyStates", "BodyTorque", "Joint",
           "JointActuation", "Mechanism", "MethodSpec", "RunFailure", "RunGrid", "SpanningTree",
           "SpringDamper", "Stepper", "SystemGraph", "UnknownAdapterError", "UnsupportedCase",
           "adapter_names", "get_adapter", "initial_state", "spanning_tree", "system_graph"]
