"""A compiled kernel called through its address (adapters/inhouse/stepping/native_call.py): the
same values as a direct call, its exceptions caught by a ``try`` around the call or raised out
of the caller, no memory kept, and a wrong use refused instead of run.

The kernels' own loops call their right-hand sides this way; that their trajectories are those
of the Python path is checked in test_compiled_path.py and test_joint_compiled_loop.py."""

import numpy as np
import pytest
from numba import njit, types
from numba.core.errors import TypingError
from numba.core.runtime import _nrt_python, rtsys

from mbh._adapters.inhouse.stepping.native_call import NativeEntry, call_native


@njit
def _scaled(q, t, weights):
    """A kernel that allocates its result and raises for t < 0."""
    if t < 0.0:
        raise ValueError("negative time")
    out = np.empty(q.shape[0])
    for i in range(q.shape[0]):
        out[i] = q[i] * weights[0][i] + t * weights[1][0]
    return out


@njit
def _sum_of_three(entry, q, t, weights):
    """Three calls through ``entry`` inside a ``try``: their sum, or -1 when one raised."""
    total = 0.0
    try:
        for k in range(3):
            total += call_native(entry, (q, t - k, weights)).sum()
    except Exception:  # noqa: BLE001 — the test's point
        return -1.0
    return total


@njit
def _one(entry, q, t, weights):
    return call_native(entry, (q, t, weights))


def _entry(q, t, weights) -> NativeEntry:
    entry = NativeEntry(_scaled, (q, t, weights), types.float64[::1])
    types_ = entry.argument_types
    _scaled.compile(types_)
    entry.resolve(_scaled.overloads[types_])
    return entry


Q = np.array([0.5, -1.0, 2.0, 0.0])
WEIGHTS = (np.array([2.0, 3.0, -1.0, 4.0]), np.array([3.0]))


def test_a_call_through_the_entry_returns_what_a_direct_call_returns():
    entry = _entry(Q, 1.0, WEIGHTS)
    np.testing.assert_array_equal(_one(entry, Q, 0.7, WEIGHTS), _scaled(Q, 0.7, WEIGHTS))
    expected = sum(_scaled(Q, 5.0 - k, WEIGHTS).sum() for k in range(3))
    assert _sum_of_three(entry, Q, 5.0, WEIGHTS) == expected


def test_the_kernels_exception_reaches_the_caller_and_nothing_is_kept():
    entry = _entry(Q, 1.0, WEIGHTS)
    assert _sum_of_three(entry, Q, 1.0, WEIGHTS) == -1.0  # the third call raises, caught
    with pytest.raises(ValueError, match="negative time"):
        _one(entry, Q, -1.0, WEIGHTS)
    enabled = _nrt_python.memsys_stats_enabled()
    _nrt_python.memsys_enable_stats()
    try:
        before = rtsys.get_allocation_stats()
        for _ in range(200):
            _sum_of_three(entry, Q, 5.0, WEIGHTS)
            _sum_of_three(entry, Q, 1.0, WEIGHTS)
        after = rtsys.get_allocation_stats()
    finally:
        if not enabled:
            _nrt_python.memsys_disable_stats()
    assert after.alloc - before.alloc >= 3 * 200  # the results were allocated ...
    assert after.alloc - before.alloc == after.free - before.free  # ... and all freed
    assert after.mi_alloc - before.mi_alloc == after.mi_free - before.mi_free


def test_an_entry_not_resolved_raises_instead_of_jumping():
    entry = NativeEntry(_scaled, (Q, 1.0, WEIGHTS), types.float64[::1])
    with pytest.raises(RuntimeError, match="called before it was resolved"):
        _one(entry, Q, 1.0, WEIGHTS)


def test_other_argument_types_do_not_compile():
    entry = _entry(Q, 1.0, WEIGHTS)
    with pytest.raises(TypingError, match="takes"):
        _one(entry, Q.astype(np.float32), 1.0, WEIGHTS)


def test_a_version_of_another_return_type_is_refused():
    entry = NativeEntry(_scaled, (Q, 1.0, WEIGHTS), types.float64[:])
    types_ = entry.argument_types
    _scaled.compile(types_)
    with pytest.raises(TypeError, match="was compiled as"):
        entry.resolve(_scaled.overloads[types_])
    assert entry.address == 0
