"""One writer per run: a run folder's ``.writer.lock``, a file locked with ``flock``, which the
kernel releases when its process ends (however it ends), so a dead writer's lock is taken over
by the next one.  The file says who holds it.
"""

from __future__ import annotations

import fcntl
import os
from pathlib import Path

from mbh._harness.common.errors import MbhError
from mbh._harness.store.manifest import timestamp

__all__ = ["WRITER_LOCK", "RunLocked", "lock_run_folder"]

#: The writer lock's file name in a run folder.
WRITER_LOCK = ".writer.lock"


class RunLocked(MbhError, RuntimeError):
    """Another live process is writing the run; the message names its pid and start time."""


def lock_run_folder(path: Path):
    """Take ``path``'s writer lock without waiting and record who holds it; the returned open
    file holds the lock until it is closed or the process ends.  Raises :class:`RunLocked`."""
    handle = open(path / WRITER_LOCK, "a+", encoding="utf-8")
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        handle.seek(0)
        holder = handle.read().strip() or "a process that has not said who it is"
        handle.close()
        raise RunLocked(f"{path}: the run is being written by {holder}; one process writes a "
                        f"run at a time (stop that one, e.g. with Ctrl-C, then --resume)") from None
    handle.seek(0)
    handle.truncate()
    handle.write(f"process {os.getpid()}, started {timestamp()}")
    handle.flush()
    return handle
