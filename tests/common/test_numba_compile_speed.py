"""The replacements of mbh._harness.common.numba_compile_speed answer as numba's own methods and
leave the compiled code unchanged."""

from __future__ import annotations

import itertools
import re

import numpy as np
import pytest
from numba import njit
from numba.core import compiler

from mbh._harness.common import numba_compile_speed

#: Boolean options of numba's compiler flags the comparison is tried on, each unset, set to
#: False or set to True on either side (3^4 states a side).
OPTIONS = ("boundscheck", "debuginfo", "no_cpython_wrapper", "enable_looplift")


def _flags(state: tuple) -> compiler.Flags:
    flags = compiler.Flags()
    for name, value in zip(OPTIONS, state):
        if value is not None:
            setattr(flags, name, value)
    return flags


def test_flags_hash_and_equality_answer_as_numbas_own():
    states = [_flags(state) for state in itertools.product((None, False, True),
                                                           repeat=len(OPTIONS))]
    original_hash, original_eq = (numba_compile_speed.ORIGINAL[key] for key in ("hash", "eq"))
    for mine in states:
        assert numba_compile_speed.flags_hash(mine) == original_hash(mine)
        for theirs in states:
            assert numba_compile_speed.flags_equal(mine, theirs) == original_eq(mine, theirs)
    assert numba_compile_speed.flags_equal(states[0], 1) is NotImplemented


def test_applies_to_the_series_written_for_only():
    assert numba_compile_speed.applies("0.68.1")
    assert not numba_compile_speed.applies("0.69.0")
    assert not numba_compile_speed.applies("1.68.0")


def _nested_inline_function():
    """A fresh function calling two levels of ``inline="always"`` functions and an inlined
    numpy overload (new dispatchers at each call: nothing is shared between compilations)."""

    @njit(inline="always")
    def weighted_sum(values, weight):
        total = 0.0
        for i in range(values.shape[0]):
            total += values[i] * weight
        return total

    @njit(inline="always")
    def both(values):
        return weighted_sum(values, 2.0) + np.sum(values) - weighted_sum(values, 0.5)

    def top(values):
        return both(values) * both(values[1:])

    return njit(top)


def _llvm_text(installed: bool) -> str:
    """The optimised LLVM IR of :func:`_nested_inline_function`, compiled with or without the
    replacements, with what names a compilation (numbers: unique ids, name lengths) and the
    alignment of comments taken out."""
    (numba_compile_speed.install if installed else numba_compile_speed.uninstall)()
    function = _nested_inline_function()
    function(np.arange(5.0))
    text = function.inspect_llvm(function.signatures[0])
    return re.sub(r"[ \t]+", " ", re.sub(r"\d+", "N", text))


@pytest.fixture
def replacements_back_afterwards():
    """The replacements in place again after a test that took them out."""
    yield
    numba_compile_speed.install()


@pytest.mark.usefixtures("replacements_back_afterwards")
def test_inlining_without_copies_compiles_the_same_code():
    as_shipped = _llvm_text(installed=False)
    assert _llvm_text(installed=False) == as_shipped  # the comparison sees no compilation's ids
    assert _llvm_text(installed=True) == as_shipped
