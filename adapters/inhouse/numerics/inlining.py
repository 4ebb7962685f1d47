"""Where numba inlines the in-house kernels' small helpers: into the compiled loops, not into a
kernel that Python calls by itself.

The helpers of :mod:`~mbh._adapters.inhouse.bodies.bodykin` and
:mod:`~mbh._adapters.inhouse.bodies.kernels` are inlined into their compiled callers, because a
call of a separately compiled function with array arguments costs more than their few flops.
Inlined, numba types and compiles their code again at every call site: Φ, Φ_q and γ call them at
~20 sites each, and compiling γ alone took 10.4 s (Φ_q 5.4 s, Φ 2.4 s) of the 34 s a first
in-house case waited on a machine where nothing was compiled, where Python calls each of them a
few times at the start (assembly, rank analysis, the conditioning indicator).  Inside a loop
that calls them every step the inlining pays; for a handful of calls from Python it does not.

So the helpers are inlined by a cost model (numba's ``inline=`` callable, called with the call
expression, the IR of the function being compiled and the callee's IR): everywhere except into a
kernel marked :func:`called_from_python` when that kernel is compiled by itself.  Where such a
kernel is itself inlined into a compiled caller, the caller's IR is the one being compiled, so
its helpers are inlined there as before: the loops compile to the same code.  Inlining or not
changes no floating-point operation (numba compiles without fast-math), so both versions return
the same bits.
"""

from __future__ import annotations

#: The attribute :func:`called_from_python` sets on a kernel's Python function.
_ENTRY_MARK = "_mbh_called_from_python"


def called_from_python(dispatcher):
    """Mark ``dispatcher`` (an ``@njit`` kernel) as one that Python calls by itself: compiled
    alone, it calls its helpers instead of inlining them (:func:`into_compiled_callers`).  Apply
    it above ``@njit``, so that the mark is there before any compilation."""
    setattr(dispatcher.py_func, _ENTRY_MARK, True)
    return dispatcher


def into_compiled_callers(expr, caller_ir, callee_ir) -> bool:
    """numba's inlining cost model: inline the callee unless the function being compiled
    (``caller_ir``, into which earlier inlining has already expanded) is marked
    :func:`called_from_python`."""
    return not getattr(caller_ir.func_id.func, _ENTRY_MARK, False)
