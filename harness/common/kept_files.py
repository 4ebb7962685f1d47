"""Files read once by the warm template and kept in memory for the cases forked from it.

Each case's process is forked from the warm template (:mod:`mbh._harness.run.warm`), and a case's first
call of anything costs it the copy-on-write faults of the pages it touches (~3.5 µs each on the
2-core development machine): parsing a scenario file took a forked case ~5 ms, decompressing its
reference 4–23 ms.  The template reads the campaign's scenario and reference files inside
:func:`keeping`; what it read there is kept, and a later read of the same files, in the template or
in any process forked from it, returns the kept value instead of reading again.

A kept value is returned only while every file it was read from still has the identity it had
(:func:`identity`: device, inode, size, modification and change times, ns): a file replaced (as
this project writes references and reports: a new file moved into place) or rewritten is read
again.  The one change it does not see is an in-place rewrite to the same size within the file
system's timestamp resolution (a few ms) of the template's read.  Nothing is kept outside
:func:`keeping`, so a process that never enters it (the campaign's own process, the tests) always
reads the files.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path
from typing import Callable, TypeVar

T = TypeVar("T")

#: (kind, identity of each file) → the value read.
_KEPT: dict[tuple, object] = {}
_keeping = False


def identity(path: Path) -> tuple | None:
    """(path, device, inode, size, mtime ns, ctime ns) of ``path``, or None when it cannot be
    stat'ed (missing, unreadable, or a name the system refuses, such as one with a null byte)."""
    try:
        stat = os.stat(path)
    except (OSError, ValueError):
        return None
    return (str(path), stat.st_dev, stat.st_ino, stat.st_size, stat.st_mtime_ns, stat.st_ctime_ns)


@contextlib.contextmanager
def keeping():
    """Within the block, every :func:`read_kept` read is kept (the warm template's preload)."""
    global _keeping
    _keeping = True
    try:
        yield
    finally:
        _keeping = False


def read_kept(kind: str, paths: tuple[Path, ...], read: Callable[[], T]) -> T:
    """``read()``, the reading of ``paths`` as ``kind`` (e.g. ``"scenario"``), or the value kept
    for these files as they are now; within :func:`keeping` the value read is kept.  A value is
    kept only when ``read`` returned without raising and every file could be stat'ed."""
    key = (kind, *(identity(path) for path in paths))
    if None not in key and key in _KEPT:
        return _KEPT[key]
    value = read()
    if _keeping and None not in key:
        _KEPT[key] = value
    return value
