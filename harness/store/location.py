"""Where the results live: the results root (``$MBH_RESULTS_DIR``, the checkout's ``results``
or the user data folder's) and the check, before a run starts, that it can take one.
"""

from __future__ import annotations

import os
import shutil
import threading
from pathlib import Path

from mbh._harness.common.locations import checkout, user_data
from mbh._harness.store.files import write_bytes
from mbh._harness.store.problems import StoreError, write_problem

__all__ = ["ROOT_ENV", "MIN_FREE_BYTES", "results_root", "root_or_default", "check_writable"]

#: Environment variable naming the results root.
ROOT_ENV = "MBH_RESULTS_DIR"

#: Least free space on the results root's disk for a run to start, bytes: room for the manifest,
#: the first parts and trajectories (a case stores a ~10 kB part and a trajectory of at most
#: ~0.5 MB, the 4 s of the largest shipped scene), so a nearly full disk fails before any case.
MIN_FREE_BYTES = 16 * 2**20
#: Size of the probe file :func:`check_writable` writes, bytes.
_PROBE_BYTES = 64 * 2**10


def results_root() -> Path:
    """The results root: ``$MBH_RESULTS_DIR`` if set, else ``results`` in the checkout the harness
    runs from, else ``results`` in the user data folder (an installed harness never writes into
    its own package)."""
    configured = os.environ.get(ROOT_ENV)
    if configured:
        return Path(configured)
    repository = checkout()
    return (repository if repository is not None else user_data()) / "results"


def root_or_default(root) -> Path:
    """``root`` as a path, or :func:`results_root` when it is None."""
    return Path(root) if root is not None else results_root()


def check_writable(root: Path | None = None) -> Path:
    """Fail early when the results root cannot take a run: create it if needed, write, sync and
    remove a probe file in it, and require :data:`MIN_FREE_BYTES` free on its disk.

    Parameters
    ----------
    root : Path, optional
        The results root (default :func:`results_root`).

    Returns
    -------
    Path
        The root.

    Raises
    ------
    StoreError
        Naming the root and the problem (not a folder, read-only, full).
    """
    root = root_or_default(root)
    if root.exists() and not root.is_dir():
        raise StoreError(f"results root {root}: not a folder")
    probe = root / f".write-probe-{os.getpid()}-{threading.get_ident()}"
    try:
        root.mkdir(parents=True, exist_ok=True)
        write_bytes(probe, bytes(_PROBE_BYTES))
        probe.unlink()
        free = shutil.disk_usage(root).free
    except OSError as error:
        raise StoreError(f"results root {root}: " + write_problem(root, error)) from None
    if free < MIN_FREE_BYTES:
        raise StoreError(f"results root {root}: only {free / 2**20:.1f} MiB free on its "
                         f"disk; a run needs at least {MIN_FREE_BYTES / 2**20:g} MiB "
                         f"(the disk is full)")
    return root
