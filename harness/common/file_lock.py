"""A lock between the processes of one machine, for work one of them should do while the others
wait: compiling a function into a cache they share (a campaign's workers, pytest-xdist's workers,
two terminals), where each would otherwise compile the same function at once and write the same
files.

The lock is ``flock`` on a file beside the cache (POSIX; released by the kernel when its holder
dies, so a killed compiler never blocks the others).  Where ``fcntl`` is missing or the lock file
cannot be made, the work runs without it: the caches are written whole either way, so the only
loss is the duplicated work.  A process must not take a lock it holds already (``flock`` on a
second open file would wait for itself); :func:`acquire` refuses that with None.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO

try:
    import fcntl
except ImportError:  # not POSIX: no lock, only duplicated work
    fcntl = None

#: The lock files this process holds.
_HELD: set[Path] = set()


class Lock:
    """A held lock (:func:`acquire`); :func:`release` it once."""

    def __init__(self, path: Path, handle: IO[bytes]):
        self.path, self.handle = path, handle


def acquire(path: Path) -> Lock | None:
    """Take the exclusive lock on ``path`` (made with its folder if missing), waiting for any
    other process that holds it; None where there can be no lock (see the module notes) or this
    process holds it already."""
    path = Path(path)
    if fcntl is None or path in _HELD:
        return None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        handle = open(path, "a+b")
    except OSError:
        return None
    fcntl.flock(handle, fcntl.LOCK_EX)
    _HELD.add(path)
    return Lock(path, handle)


def release(lock: Lock | None) -> None:
    """Release a lock :func:`acquire` took (None: nothing)."""
    if lock is None:
        return
    _HELD.discard(lock.path)
    try:
        fcntl.flock(lock.handle, fcntl.LOCK_UN)
    finally:
        lock.handle.close()


@contextmanager
def held(path: Path) -> Iterator[None]:
    """Hold the exclusive lock on ``path`` inside the block (:func:`acquire`)."""
    lock = acquire(path)
    try:
        yield
    finally:
        release(lock)
