"""PyBullet, imported with its console output silenced, and the context manager that silences it.

PyBullet writes from C straight to file descriptors 1 and 2 (a build-time banner on import, the
MLCP solvers' announcements later).  Every module of this package takes ``pybullet`` from here, so
the import is silenced whichever module is imported first.
"""

from __future__ import annotations

__all__ = ["_quiet_output", "pybullet"]

import contextlib
import ctypes
import os
from collections.abc import Iterator


def _flush_c_stdout() -> None:
    """Flush the C library's ``stdout`` buffer (a message may still sit in it)."""
    libc = ctypes.CDLL(None)
    try:
        libc.fflush(ctypes.c_void_p.in_dll(libc, "stdout"))
    except ValueError:
        libc.fflush(None)


@contextlib.contextmanager
def _quiet_output() -> Iterator[None]:
    """Silence C-level writes to file descriptors 1 and 2 (PyBullet's banners: the build-time
    banner goes to stderr on import, the MLCP solver announcements to stdout)."""
    try:
        saved = [os.dup(1), os.dup(2)]
    except OSError:
        yield
        return
    try:
        with open(os.devnull, "wb") as devnull:
            os.dup2(devnull.fileno(), 1)
            os.dup2(devnull.fileno(), 2)
            yield
    finally:
        _flush_c_stdout()
        for fd, copy in zip((1, 2), saved):
            os.dup2(copy, fd)
            os.close(copy)


with _quiet_output():
    import pybullet
