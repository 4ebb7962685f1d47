"""A lock between the processes of one machine, for work one of them should do while the others
wait: compiling a function into a cache they share (a campaign's workers, pytest-xdist's workers,
two terminals), where each would otherwise compile the same function at once and write the same
files.

The lock is ``flock`` on a file beside the cache (POSIX; released by the kernel when its holder
dies, so a killed compiler never blocks the others).  Where ``fcntl`` is missing or the lock file
cannot be made, the block runs without it: the caches are written whole either way, so the only
loss is the duplicated work.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

try:
    import fcntl
except ImportError:  # not POSIX: no lock, only duplicated work
    fcntl = None


@contextmanager
def held(path: Path) -> Iterator[None]:
    """Hold the exclusive lock on ``path`` (made with its folder if missing) inside the block,
    waiting for any other process that holds it."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        handle = open(path, "a+b")
    except OSError:
        handle = None
    if handle is None or fcntl is None:
        yield
        return
    with handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)
