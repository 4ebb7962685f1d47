"""Two of numba's compile-time costs taken out, without changing what it compiles.

Profiled on a machine with nothing compiled (docs/speed.md, "What a first run compiles"), 78 of
the 280 profiled seconds of compiling the in-house kernels went to two pieces of bookkeeping:

* **Comparing compiler flags.**  Every typing of a call to an ``@overload``-ed function (each
  numpy call, each ``len``, …) looks its implementation up in a cache keyed by the compiler's
  flags (``numba.core.typing.templates._OverloadFunctionTemplate._get_impl``).  A flags object
  (``numba.core.targetconfig.TargetConfig``) compares equal by building the dictionary of all its
  22 options through their properties, on both sides, and hashes by building it and sorting it:
  ~200,000 lookups and ~470,000 comparisons for the one-step loop and its right-hand side, 34 of
  the profiled seconds.
  :func:`flags_equal` compares only the options either side has set (an unset option is its
  default on both sides, so the answer is the same); :func:`flags_hash` returns numba's own
  value, which depends on the class alone (``sorted`` of the dictionary sorts its keys, the
  option names), computed once per class.
* **Copying an inlined function's IR twice.**  At each call of a function declared
  ``inline="always"``, numba's inliner (``numba.core.inline_closurecall.InlineWorker``) runs the
  callee's untyped passes afresh, then deep-copies the fresh IR twice, block by block: once to
  protect it and once to hand back an unchanged copy, which its only caller here
  (``InlineInlinables``) discards.  The fresh IR belongs to that one call, so
  :func:`inline_function` inlines it without the copies (``copy.deepcopy`` in the inliner's
  module returns its argument for the duration).  Inlined overloads (``typed_passes``), whose
  IR numba keeps and reuses, still take the copies.

Neither changes what numba compiles: the optimised LLVM IR of a function with nested inlined
calls is the same with and without them (``tests/common/test_numba_compile_speed.py``), and five
warm-up cases on the four-bar step to the same bits from caches compiled either way.  The
one-step loop's case of the warm-up and the kernels' right-hand side compiled in 140 s instead
of 174 s (side by side, one core each).  The replacements are installed only for the numba
series they were written against (:data:`WRITTEN_FOR`); with another numba they are left out
and numba compiles as it ships.
"""

from __future__ import annotations

import contextlib
import copy
import functools
import logging

import numba
from numba.core import inline_closurecall, targetconfig

#: numba's (major, minor) release series whose internals the replacements were written against.
WRITTEN_FOR = ((0, 68),)
#: numba's own methods, kept for the check of the replacements and for :func:`uninstall`.
ORIGINAL = {
    "hash": targetconfig.TargetConfig.__hash__,
    "eq": targetconfig.TargetConfig.__eq__,
    "inline_function": inline_closurecall.InlineWorker.inline_function,
}

LOG = logging.getLogger(__name__)


def applies(version: str = numba.__version__) -> bool:
    """Whether the replacements were written for numba ``version`` ("0.68.1")."""
    major, minor = (int(part) for part in version.split(".")[:2])
    return (major, minor) in WRITTEN_FOR


@functools.cache
def _class_hash(cls: type) -> int:
    """numba's ``TargetConfig.__hash__`` of any instance of ``cls``: the hash of its sorted
    option names."""
    return hash(tuple(sorted(cls.options)))


def flags_hash(self: targetconfig.TargetConfig) -> int:
    """``TargetConfig.__hash__``, the value numba's gives, once per class."""
    return _class_hash(type(self))


def flags_equal(self: targetconfig.TargetConfig, other: object):
    """``TargetConfig.__eq__``: every option's value (the default where it is not set) equal,
    compared on the options either side has set."""
    if not isinstance(other, targetconfig.TargetConfig):
        return NotImplemented
    if self.options is not other.options:  # flags of two kinds: numba's own comparison
        return ORIGINAL["eq"](self, other)
    mine, theirs = self._values, other._values
    if mine == theirs:
        return True
    options = self.options
    return all(mine.get(name, options[name].default) == theirs.get(name, options[name].default)
               for name in mine.keys() | theirs.keys())


class _NoCopy:
    """Stands for the ``copy`` module inside numba's inliner while it inlines a fresh IR."""

    @staticmethod
    def deepcopy(value, memo=None):
        return value


@contextlib.contextmanager
def _fresh_ir():
    """The inliner's ``copy.deepcopy`` returns its argument inside the block."""
    inline_closurecall.copy = _NoCopy
    try:
        yield
    finally:
        inline_closurecall.copy = copy


def inline_function(self, caller_ir, block, i, function, arg_typs=None):
    """``InlineWorker.inline_function`` without the two copies of the callee's IR, which
    :meth:`run_untyped_passes` has just made for this call alone."""
    callee_ir = self.run_untyped_passes(function)
    with _fresh_ir():
        return self.inline_ir(caller_ir, block, i, callee_ir, function.__code__.co_freevars,
                              arg_typs=arg_typs)


def install() -> None:
    """Put the replacements in place if :func:`applies` (once per process; numba holds its
    compiler lock while it compiles, so the inliner's swap is never seen by another thread)."""
    if not applies():
        LOG.debug("numba %s: compiling as it ships (replacements written for %s)",
                  numba.__version__, WRITTEN_FOR)
        return
    targetconfig.TargetConfig.__hash__ = flags_hash
    targetconfig.TargetConfig.__eq__ = flags_equal
    inline_closurecall.InlineWorker.inline_function = inline_function


def uninstall() -> None:
    """numba's own methods back (for the tests that compare both)."""
    targetconfig.TargetConfig.__hash__ = ORIGINAL["hash"]
    targetconfig.TargetConfig.__eq__ = ORIGINAL["eq"]
    inline_closurecall.InlineWorker.inline_function = ORIGINAL["inline_function"]
