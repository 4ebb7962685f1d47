"""The LLVM optimisation level of the in-house kernels and generated functions: 2, not numba's 3.

numba optimises every function it compiles with LLVM's passes at ``numba.config.OPT`` (3 unless
``NUMBA_OPT`` says otherwise).  On the kernels
(:data:`~mbh._harness.common.kernel_cache.KERNEL_PACKAGES`) level 3 buys nothing that level 2
does not.  Every warm-up case compiled at both levels, one process each on an empty cache,
stepped to the same bits (fifteen runs: the compiled one-step, partitioned, multistep,
joint-coordinate and generated loops, Bricard on the kernels, the Python path), and the bare
loops stepped as fast (best of three alternating rounds, level 2 against 3: 0.94–1.04, within
the rounds' own spread).  Compiling took 176 s instead of 197 s with ``NUMBA_OPT=2`` for the
whole process, and 192 s instead of 203 s with the level scoped as here (docs/speed.md, "LLVM's
level 2 for the kernels").  numba compiles without fast-math, so neither level may reorder a
floating-point operation: the bits are the same by construction, and the tests compare them
(``tests/common/test_kernel_opt_level.py``).

The level is set only while numba compiles a function of a package that asked for it (the
kernel packages, from their ``__init__``: :func:`install`; a ``numba:compile`` event listener,
:class:`KernelLevel`) or a generated module (:func:`at_kernel_level`), and put back afterwards,
so a user's own numba code in the same process compiles at the level it would have had.  The
level of LLVM's machine-code generation is the target machine's, fixed by numba when it first
compiles anything in the process, and is left as it is.  :data:`LEVEL` is part of the kernels'
cache fingerprint (:func:`~mbh._harness.common.kernel_cache.toolchain`), so a cache compiled at
another level is not loaded.
"""

from __future__ import annotations

import contextlib

from numba.core import config, event

#: LLVM's optimisation level of the kernels' and generated functions' passes.
LEVEL = 2
#: The packages (module names) whose functions compile at :data:`LEVEL`: :func:`install`'s.
_PACKAGES: set[str] = set()


@contextlib.contextmanager
def at_kernel_level():
    """Compile at :data:`LEVEL` inside the block, then put numba's level back."""
    before = config.OPT
    config.OPT = config._OptLevel(LEVEL)
    try:
        yield
    finally:
        config.OPT = before


class KernelLevel(event.Listener):
    """Sets :data:`LEVEL` from the start of a kernel package's function's compilation to its end
    (numba's ``numba:compile`` event); the callees it compiles meanwhile inherit it."""

    def __init__(self):
        self._levels = []  # the level before each compilation in progress, innermost last

    def on_start(self, event_):
        self._levels.append(config.OPT)
        if _defined_in_kernels(event_.data["dispatcher"]):
            config.OPT = config._OptLevel(LEVEL)

    def on_end(self, event_):
        config.OPT = self._levels.pop()


def _defined_in_kernels(dispatcher) -> bool:
    module = getattr(getattr(dispatcher, "py_func", None), "__module__", "") or ""
    return any(module == package or module.startswith(f"{package}.") for package in _PACKAGES)


_LISTENER = KernelLevel()


def install(package: str) -> None:
    """Compile the functions of ``package`` (its ``__name__``) and of its modules at
    :data:`LEVEL`; the listener is registered once per process."""
    _PACKAGES.add(package)
    if _LISTENER not in event._registered.get("numba:compile", []):
        event.register("numba:compile", _LISTENER)
