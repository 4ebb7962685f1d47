"""What the measuring stick derives from a scene's verified reference alone, computed once per
reference and kept.

Every case of a scene is judged against the same reference, and the stick derived the same
figures from it in every case: the energy scale (twice: verdict and metrics), the reference's
energy-balance baseline, its driver series and markers and the branch check's premise.  In a
campaign each case runs in a process forked from the warm template (:mod:`harness.run.warm`),
which reads the reference once and computes these once (:func:`prepare`), so the cases find them.

A value is kept only for a reference whose arrays are all read-only, as the reference store
returns them (:func:`harness.store.reference_files.read_unchecked`): a trajectory that can change
could make a kept value stale.  Values are keyed by the function, the mechanism's content hash
(equal hashes: equal mechanisms) and the reference object itself, and are the values the function
returns; the last :data:`MAX_ENTRIES` are kept.
"""

from __future__ import annotations

import functools
from collections import OrderedDict
from typing import Callable, TypeVar

import numpy as np

from harness.model.mechanism import Mechanism
from harness.model.trajectory import Trajectory

T = TypeVar("T")

#: Values kept at most (a campaign judges against one reference per scene).
MAX_ENTRIES = 256

#: (function, content hash, id(reference), other arguments) → (reference, value); the reference
#: is held so that its id cannot be reused by another object while its entry is kept.
_KEPT: OrderedDict[tuple, tuple[Trajectory, object]] = OrderedDict()

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
        key = (function.__qualname__, mech.content_hash, id(reference), args)
        entry = _KEPT.get(key)
        if entry is not None and entry[0] is reference:
            _KEPT.move_to_end(key)
            return entry[1]
        value = function(mech, reference, *args)
        _KEPT[key] = (reference, value)
        while len(_KEPT) > MAX_ENTRIES:
            _KEPT.popitem(last=False)
        return value

    return kept
