"""What the measuring stick derives from a scene's verified reference alone, computed once per
reference and kept.

Every case of a scene is judged against the same reference, and the stick derived the same
figures from it in every case: the energy scale (twice: verdict and metrics), the reference's
energy-balance baseline, its driver series and markers, the branch check's premise and its
outputs.  In a campaign each case runs in a process forked from the warm template
(:mod:`mbh._harness.run.warm`), which reads the reference once and computes these once
(:func:`mbh._harness.measure.verdict.prepare_reference`), so the cases find them.

A value is kept only for a reference whose arrays are all read-only, as the reference store
returns them (:func:`mbh._harness.store.reference_files.read_unchecked`): a trajectory that can change
could make a kept value stale.  Values are keyed by the reference object itself, the function
and the mechanism's content hash (equal hashes: equal mechanisms), and are the values the function
returns; those of the last :data:`MAX_REFERENCES` references used are kept.
"""

from __future__ import annotations

import functools
from collections import OrderedDict
from typing import Callable, TypeVar

import numpy as np

from mbh._harness.model.mechanism import Mechanism
from mbh._harness.model.trajectory import Trajectory

T = TypeVar("T")

#: References whose values are kept at most (the least recently used leave first).  Each holds
#: its reference alive, a few MB for a long reference; a campaign has one per scene (10 in each
#: shipped campaign).
MAX_REFERENCES = 24

#: id(reference) → (reference, {(function, content hash, other arguments): value}); the reference
#: is held so that its id cannot be reused by another object while its values are kept.
_KEPT: OrderedDict[int, tuple[Trajectory, dict]] = OrderedDict()

#: The arrays of a trajectory that must all be read-only for its values to be kept.
ARRAYS = ("times", "position", "quaternion", "velocity", "angular_velocity")


def is_frozen(reference: Trajectory) -> bool:
    """Whether every array of ``reference`` is read-only (so nothing kept about it can go
    stale)."""
    return not any(getattr(reference, name).flags.writeable for name in ARRAYS)


def read_only(array: np.ndarray) -> np.ndarray:
    """``array``, made read-only (a kept value's arrays: no caller may change them)."""
    array.flags.writeable = False
    return array


def per_reference(function: Callable[..., T]) -> Callable[..., T]:
    """``function(mech, reference, *args)`` (hashable ``args``), kept per frozen reference."""

    @functools.wraps(function)
    def kept(mech: Mechanism, reference: Trajectory, *args):
        if not mech.content_hash or not is_frozen(reference):
            return function(mech, reference, *args)
        entry = _KEPT.get(id(reference))
        if entry is None or entry[0] is not reference:
            entry = _KEPT[id(reference)] = (reference, {})
            while len(_KEPT) > MAX_REFERENCES:
                _KEPT.popitem(last=False)
        _KEPT.move_to_end(id(reference))
        key = (function.__qualname__, mech.content_hash, args)
        if key not in entry[1]:
            entry[1][key] = function(mech, reference, *args)
        return entry[1][key]

    return kept
