"""What a run's manifest records about where it ran: the repository's git state, the versions
of the packages that compute results, and the machine."""

from __future__ import annotations

import hashlib
import importlib.metadata
import json
import os
import platform
import re
import subprocess
from pathlib import Path

from mbh._harness.common.locations import ADAPTERS_FOLDER, CODE_ROOT, HARNESS_FOLDER, checkout

#: Packages whose versions every manifest records.
RECORDED_PACKAGES = ("numpy", "scipy", "pandas", "pyarrow", "mujoco", "pin", "exudyn",
                     "pybullet", "scikit-sundae", "numba")

#: The folder holding the harness's code folders (a checkout, or the installed mbh package).
_REPO = CODE_ROOT
#: The project's code folders whose code computes a case's row (the engines' calls, the measuring
#: stick, the metrics), relative to :data:`_REPO`.
COMPUTING_PACKAGES = (HARNESS_FOLDER.name, ADAPTERS_FOLDER.name)


def _git(*args: str) -> str | None:
    """Output of ``git args`` in the harness's checkout; None for an installed harness (whose
    folder may sit inside another project's repository) or when git fails."""
    repository = checkout()
    if repository is None:
        return None
    try:
        done = subprocess.run(["git", "-C", str(repository), *args], capture_output=True, text=True,
                              timeout=30, check=False)
    except (OSError, subprocess.SubprocessError):
        return None
    return done.stdout if done.returncode == 0 else None


def git_state() -> dict:
    """``{"commit": sha or None, "dirty": bool or None}`` of the repository (None: no git)."""
    commit = _git("rev-parse", "HEAD")
    status = _git("status", "--porcelain", "--untracked-files=no")
    return {"commit": commit.strip() if commit else None,
            "dirty": None if status is None else bool(status.strip())}


def package_versions() -> dict[str, str | None]:
    """Installed version of each of :data:`RECORDED_PACKAGES` (None when not installed)."""
    versions = {}
    for name in RECORDED_PACKAGES:
        try:
            versions[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            versions[name] = None
    return versions


def code_fingerprint() -> str:
    """SHA-256 (hex) of what computes a case's row besides its inputs: the path and content of
    every Python file of :data:`COMPUTING_PACKAGES` and :func:`package_versions`.  Any edit to the
    harness or an adapter, or another numpy, numba or engine version, changes it."""
    digest = hashlib.sha256(json.dumps(package_versions(), sort_keys=True).encode())
    for package in COMPUTING_PACKAGES:
        for path in sorted((_REPO / package).rglob("*.py")):
            digest.update(path.relative_to(_REPO).as_posix().encode() + b"\0")
            digest.update(path.read_bytes() + b"\0")
    return digest.hexdigest()


def _cpu_model() -> str:
    try:
        text = Path("/proc/cpuinfo").read_text(encoding="utf-8", errors="replace")
    except OSError:
        return platform.processor()
    found = re.search(r"^model name\s*:\s*(.+)$", text, re.MULTILINE)
    return found.group(1).strip() if found else platform.processor()


def machine() -> dict:
    """Platform, CPU model and count, Python version and host of this machine."""
    usable = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None
    return {"platform": platform.platform(), "machine": platform.machine(),
            "processor": _cpu_model(), "cpu_count": os.cpu_count(), "usable_cpus": usable,
            "python": platform.python_version(), "node": platform.node()}


