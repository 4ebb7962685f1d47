"""The compiled loops, made when a run first needs them: once per machine and code, by one
process while the others wait (:mod:`mbh._harness.common.file_lock`), and announced when that takes
long (:mod:`mbh._harness.common.waits`).

numba compiles a function at its first call for the argument types of that call, or loads it
from its cache (:mod:`mbh._harness.common.kernel_cache`).  The stepper asks here instead: for the
compiled function of a loop (:func:`entry`), and beforehand whether that loop is ready on this
machine (:func:`is_ready`), so that a run can take a path that compiles in seconds (the generated
steps alone) rather than wait a minute or more for the kernels' loop it may never need
(docs/speed.md, "What a first run compiles").
"""

from __future__ import annotations

import hashlib

from mbh._harness.common import file_lock, waits
from mbh._harness.common.kernel_cache import kernel_folder, mark_ready
from mbh._adapters.inhouse.stepping.native_call import NativeEntry

#: What the announcement of a loop's compilation says to expect (:func:`entry`), s: the generated
#: steps' loop compiled in 1.9 s; the one-step methods' full loop, from an empty cache once the
#: start's kernels were compiled, in 62 s, and the absolute right-hand side kernel it calls
#: through its address (:func:`resolve`,
#: :func:`~mbh._adapters.inhouse.formulations.dynamics.index1_acceleration`, its forces, Φ_q, γ
#: and solves with it) 59 s more, on the 2-core machine (2026-11-30,
#: ``benchmarks/compile_cost.py``).  The other full loops (the multistep ones) share much of that
#: code and were measured only after it (7–10 s): the full loop's figure is their estimate too.
GENERATED_LOOP_S, FULL_LOOP_S, RIGHT_HAND_SIDE_S = 2.0, 62.0, 59.0


def _types(dispatcher, args: tuple) -> tuple:
    return tuple(dispatcher.typeof_pyval(arg) for arg in args)


def _marker(dispatcher, types: tuple):
    """The file saying that ``dispatcher`` was compiled for ``types`` with this code on this
    machine (in :func:`kernel_folder`, so a change of the kernels starts without it)."""
    digest = hashlib.sha256(repr(types).encode()).hexdigest()[:16]
    return kernel_folder() / "ready" / f"{dispatcher.py_func.__name__}-{digest}"


def is_ready(dispatcher, args: tuple) -> bool:
    """Whether ``dispatcher`` for the types of ``args`` is compiled in this process or was
    compiled into the cache by any process with this code: a call would not compile it."""
    types = _types(dispatcher, args)
    return types in dispatcher.overloads or _marker(dispatcher, types).exists()


def entry(dispatcher, args: tuple, what: str, estimate_s: float):
    """The compiled function of ``dispatcher`` for the types of ``args``, called without the
    dispatcher's typing of every call (~0.3 ms for the stepper's model tuple, whose generated
    functions numba types in Python): every later call must pass arguments of the same types.

    Compiled, or loaded from numba's cache, now if needed; a compilation is announced as
    ``what``, expected to take ``estimate_s``.  A second process that wants the same loop meanwhile
    waits for the first (the loop's lock here, so that it does not announce a compilation it will
    not make; the kernels' own locks, :mod:`mbh._harness.common.kernel_cache`) and then loads it.
    """
    return _overload(dispatcher, _types(dispatcher, args), what, estimate_s).entry_point


def resolve(native: NativeEntry, what: str, estimate_s: float) -> None:
    """Point ``native`` at its kernel, compiled (announced as ``what``, expected to take
    ``estimate_s``) or loaded now if it is not yet, as :func:`entry` does for a loop."""
    if not native.address:
        native.resolve(_overload(native.dispatcher, native.argument_types, what, estimate_s))


def _overload(dispatcher, types: tuple, what: str, estimate_s: float):
    """``dispatcher``'s compiled version (``CompileResult``) for ``types``: :func:`entry`."""
    overload = dispatcher.overloads.get(types)
    if overload is None:
        name = dispatcher.py_func.__name__
        marker = _marker(dispatcher, types)
        with file_lock.held(kernel_folder() / "locks" / f"{name}.lock"):
            if marker.exists():
                dispatcher.compile(types)
            else:
                with waits.said(f"compiling {what}", "once on this machine", estimate_s):
                    dispatcher.compile(types)
                mark_ready(marker)
        overload = dispatcher.overloads[types]
    return overload
