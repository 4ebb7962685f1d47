"""While ``mbh warm-up`` compiles, the other processes that use the same compiled kernels wait for
it before their first kernel, so that what they run and the path they take are what they would be
after it (docs/speed.md, "What a first run compiles").

``mbh warm-up -- COMMAND`` runs COMMAND (``make test``'s pytest) beside the compilation: work that
needs no in-house or neutral kernel goes on, and the first use of one in any process (a kernel
loaded from numba's cache or compiled, a loop's readiness asked, a generated function looked up,
a campaign's case started) waits until the warm-up has ended.  Without this gate such a process
would compile what the warm-up has not reached yet, by itself, or take another path because a
loop is not compiled yet (``loop=auto``), and a case would spend its wall-clock limit waiting.

The gate is ``flock`` on a file in the kernels' fingerprint folder
(:func:`mbh._harness.common.kernel_cache.kernel_folder`): the warm-up holds it exclusively
(:func:`closed`), a waiting process takes it shared and lets go at once.  The kernel releases it
when the warm-up dies, so a killed warm-up never blocks anyone.  The warm-up's own processes carry
:data:`WARMING_UP_ENV` and pass.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from mbh._harness.common import waits

try:
    import fcntl
except ImportError:  # not POSIX: no gate, the per-function locks alone
    fcntl = None

#: Set in the warm-up's own processes: they compile, they do not wait.
WARMING_UP_ENV = "MBH_WARMING_UP"


def gate_path() -> Path:
    """The gate's file, in the fingerprint folder of the kernels in use."""
    from mbh._harness.common.kernel_cache import kernel_folder

    return kernel_folder() / "warm-up.lock"


@contextmanager
def closed() -> Iterator[None]:
    """Hold the gate closed for the block (the warm-up's compilation); this process's children
    started inside the block pass it (:data:`WARMING_UP_ENV`)."""
    previous = os.environ.get(WARMING_UP_ENV)
    os.environ[WARMING_UP_ENV] = "1"
    handle = None
    try:
        if fcntl is not None:
            path = gate_path()
            path.parent.mkdir(parents=True, exist_ok=True)
            handle = open(path, "a+b")
            try:
                fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                with waits.said("waiting for another mbh warm-up to finish",
                                "it compiles the same kernels"):
                    fcntl.flock(handle, fcntl.LOCK_EX)
        yield
    finally:
        if handle is not None:
            fcntl.flock(handle, fcntl.LOCK_UN)
            handle.close()
        if previous is None:
            os.environ.pop(WARMING_UP_ENV, None)
        else:
            os.environ[WARMING_UP_ENV] = previous


def wait_for_warm_up() -> None:
    """Return once no ``mbh warm-up`` compiles the kernels in use (at once when none does, or in
    the warm-up's own processes); a wait is said (:mod:`mbh._harness.common.waits`)."""
    if fcntl is None or os.environ.get(WARMING_UP_ENV):
        return
    try:
        handle = open(gate_path(), "rb")
    except OSError:
        return  # no warm-up has run with these kernels
    with handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            with waits.said("waiting for mbh warm-up to finish compiling the in-house kernels",
                            "it runs beside this process"):
                fcntl.flock(handle, fcntl.LOCK_SH)
        fcntl.flock(handle, fcntl.LOCK_UN)
