"""Where numba caches the compiled code of the harness and the in-house formulation, placed so
that a changed kernel never loads a binary built from its old code.

numba's own cache (``cache=True``) checks a function against its own source file only: a kernel
that calls kernels of other files, or reads their constants, would load a binary built from their
old code after they change (and a run would crash or compute the old numbers).  :func:`install`
puts :class:`KernelCacheLocator` first among numba's cache locators, which places

* the cache of every function defined in :data:`KERNEL_PACKAGES` in :func:`kernel_folder`:
  ``numba/<fingerprint>`` in the user cache (:func:`mbh._harness.common.locations.user_cache`), the
  fingerprint (:func:`fingerprint`) digesting the source of every module of those packages that
  uses numba (:func:`kernel_sources`) and the Python, numba and llvmlite versions.  An edit to any of them, or another numba, makes a new
  folder, compiled afresh (minutes, once); going back to the old code finds the old folder.  The
  :data:`KEEP` folders used last stay, older ones are removed;
* the cache of a generated function (under :func:`mbh._harness.common.locations.generated_cache`)
  beside its source, so that an entry of :mod:`mbh._adapters.inhouse.codegen.generated_store` is one folder.

A kernel is compiled by one process at a time: a process that misses it in the cache takes the
kernel's lock file (``locks/`` in the fingerprint folder, :mod:`mbh._harness.common.file_lock`) and
looks again, so a second process waits for the first and loads what it saved instead of
compiling it too (pytest-xdist's workers, a campaign's cases, two terminals).

A compiled kernel calls and reads only the modules of :func:`kernel_sources` (besides numpy,
scipy's LAPACK and numba itself); the test named there checks every global each kernel reads.
A user's
``NUMBA_CACHE_DIR`` applies to other numba code, not to these functions: it is not keyed by the
code, so it would bring the stale binaries back (``NUMBA_CACHE_LOCATOR_CLASSES`` replaces every
locator, this one included).  Where the user cache cannot be written, the folder is made under
the temporary directory instead.

Numba chooses a function's locator when the function is decorated, so :func:`install` runs at
the import of the two packages (their ``__init__``), before any of their modules; every process
that imports them, a campaign's workers included, installs it itself.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import os
import shutil
import sys
import tempfile
from collections.abc import Iterable
from pathlib import Path

import llvmlite
import numba
from numba.core import caching, event

from mbh._harness.common import file_lock, kernel_opt_level, waits
from mbh._harness.common.locations import (ADAPTERS_FOLDER, CODE_ROOT, HARNESS_FOLDER,
                                           generated_cache, user_cache)

_ROOT = CODE_ROOT
#: The packages whose modules define cached kernels (``@njit(cache=True)``, ``@cfunc``).
KERNEL_PACKAGES = (ADAPTERS_FOLDER / "inhouse", HARNESS_FOLDER / "neutral")
#: Fingerprint folders kept: the one in use and the ones used last (other checkouts, branches).
KEEP = 3
#: The file of a fingerprint folder whose modification time is its last use.
LAST_USE = "last-use"


def toolchain() -> str:
    """The Python, numba and llvmlite versions and the kernels' LLVM level
    (:data:`~mbh._harness.common.kernel_opt_level.LEVEL`): a binary built by others is not
    loaded."""
    return (f"python {sys.version}; numba {numba.__version__}; llvmlite {llvmlite.__version__}; "
            f"LLVM level {kernel_opt_level.LEVEL}")


def fingerprint(files: Iterable[Path] = ()) -> str:
    """16 hex digits of SHA-256 over :func:`toolchain` and the name (relative to the checkout or
    the installed mbh package) and content of each of ``files``, in the order given."""
    digest = hashlib.sha256(toolchain().encode())
    for path in files:
        digest.update(path.relative_to(_ROOT).as_posix().encode() + b"\0")
        digest.update(path.read_bytes() + b"\0")
    return digest.hexdigest()[:16]


def kernel_sources() -> list[Path]:
    """The modules of :data:`KERNEL_PACKAGES` that use numba (their text names it), sorted: the
    jitted kernels, and so everything a compiled kernel calls or reads (checked by
    ``tests/common/test_kernel_cache.py``).  An edit elsewhere in the packages compiles nothing."""
    return sorted(path for package in KERNEL_PACKAGES for path in package.rglob("*.py")
                  if b"numba" in path.read_bytes())


@functools.cache
def kernel_fingerprint() -> str:
    """:func:`fingerprint` of :func:`kernel_sources`: names this code's compiled kernels and
    everything computed from them (a trace of the generated functions).  Computed once per
    process."""
    return fingerprint(kernel_sources())


@functools.cache
def kernel_folder() -> Path:
    """This code's folder of compiled kernels: ``numba/<kernel_fingerprint()>`` in the user cache
    (else in the temporary directory), marked used; older folders beyond :data:`KEEP` are
    removed.  Computed once per process."""
    name = kernel_fingerprint()
    user = os.getuid() if hasattr(os, "getuid") else "user"  # a per-user temporary directory
    for root in (user_cache() / "numba", Path(tempfile.gettempdir()) / f"mbh-{user}" / "numba"):
        folder = root / name
        try:
            folder.mkdir(parents=True, exist_ok=True)
            (folder / LAST_USE).touch()
        except OSError:
            continue
        _prune(root)
        return folder
    raise OSError(f"no writable folder for compiled kernels ({user_cache() / 'numba'})")


@contextlib.contextmanager
def first_use(name: str, what: str, estimate_s: float):
    """Announce the block as compiling ``what`` (:mod:`mbh._harness.common.waits`, with
    ``estimate_s``) unless a block of this ``name`` ended well before with this code on this
    machine: for the kernels called from Python (numba compiles each at its first call, so
    there is no loop to ask for)."""
    marker = kernel_folder() / "ready" / name
    if marker.exists():
        yield
        return
    with waits.said(f"compiling {what}", "once on this machine", estimate_s):
        yield
    mark_ready(marker)


def mark_ready(marker: Path) -> None:
    """Leave ``marker``, the file saying that something was compiled with this code on this
    machine (:func:`first_use`, the compiled loops of
    :mod:`mbh._adapters.inhouse.stepping.on_demand`)."""
    try:
        marker.parent.mkdir(parents=True, exist_ok=True)
        marker.touch()
    except OSError:  # an unwritable cache only loses the mark: the next run asks numba again
        pass


def _prune(root: Path) -> None:
    """Remove the fingerprint folders of ``root`` beyond the :data:`KEEP` used last."""
    def last_use(folder: Path) -> float:
        stamp = folder / LAST_USE
        return (stamp if stamp.exists() else folder).stat().st_mtime

    try:
        folders = sorted((path for path in root.iterdir() if path.is_dir()), key=last_use,
                         reverse=True)
    except OSError:  # another process pruned the same folder meanwhile
        return
    for folder in folders[KEEP:]:
        shutil.rmtree(folder, ignore_errors=True)


def cache_folder(source: Path) -> Path | None:
    """Where numba caches the functions defined in ``source``: in :func:`kernel_folder` for the
    kernel packages (one subfolder per source folder, as numba names them), beside the source for
    a generated function, None (numba's own choice) for any other code."""
    source = source.resolve()
    if any(source.is_relative_to(package) for package in KERNEL_PACKAGES):
        return kernel_folder() / KernelCacheLocator.get_suitable_cache_subpath(str(source))
    if source.is_relative_to(generated_cache().resolve()):
        return source.parent / "__pycache__"
    return None


class KernelCacheLocator(caching.InTreeCacheLocator):
    """numba's cache locator for the harness's functions (:func:`cache_folder`); declines any
    other code, which the next locator takes."""

    def __init__(self, py_func, py_file):
        super().__init__(py_func, py_file)
        self._cache_path = str(cache_folder(Path(py_file)))
        #: A kernel of KERNEL_PACKAGES (not a generated function): compiled under its lock.
        self.kernel = any(Path(py_file).resolve().is_relative_to(package)
                          for package in KERNEL_PACKAGES)

    @classmethod
    def from_function(cls, py_func, py_file):
        if cache_folder(Path(py_file)) is None:
            return None
        return super().from_function(py_func, py_file)


def install() -> None:
    """Put :class:`KernelCacheLocator` first among numba's cache locators, and lock the
    compilation of the functions it places (:func:`_locking_load`), once per process."""
    if KernelCacheLocator not in caching.CacheImpl._locator_classes:
        caching.CacheImpl._locator_classes.insert(0, KernelCacheLocator)
    if not getattr(caching.FunctionCache.load_overload, "_mbh_locking", False):
        caching.FunctionCache.load_overload = _locking_load(caching.FunctionCache.load_overload)
        caching.FunctionCache.save_overload = _unlocking_save(caching.FunctionCache.save_overload)
        event.register("numba:compile", _FailedCompileListener())


# -- one process compiles a function, the others wait and load it -----------------------------
#
# numba looks a function up in its cache (load_overload); on a miss it compiles it and saves it
# (save_overload).  For the functions KernelCacheLocator places, a miss takes the function's lock
# (mbh._harness.common.file_lock) and looks again: a process that waited finds what the holder saved
# and loads it; else it keeps the lock while numba compiles, until the save (or a failed
# compilation, _FailedCompileListener) releases it.  The call graph has no cycles, so two
# processes taking a function's lock and then its callees' cannot wait for each other.

#: Locks this process holds, by the cache (its id) whose miss took them.
_COMPILING: dict[int, file_lock.Lock] = {}


def _lock_path(cache) -> Path:
    """The lock file of the function of ``cache`` (named as numba names its cache files: module,
    qualified name, line), in :func:`kernel_folder`."""
    return kernel_folder() / "locks" / f"{cache._impl.filename_base}.lock"


def _locking_load(load):
    def load_overload(self, sig, target_context):
        data = load(self, sig, target_context)
        locator = self._impl.locator
        if data is not None or not getattr(locator, "kernel", False):
            return data  # found, or not a kernel (generated entries lock themselves)
        lock = file_lock.acquire(_lock_path(self))
        if lock is None:
            return None
        data = load(self, sig, target_context)  # saved meanwhile by the process we waited for
        if data is not None:
            file_lock.release(lock)
        else:
            _COMPILING[id(self)] = lock
        return data

    load_overload._mbh_locking = True
    return load_overload


def _unlocking_save(save):
    def save_overload(self, sig, data):
        try:
            save(self, sig, data)
        finally:
            file_lock.release(_COMPILING.pop(id(self), None))

    return save_overload


class _FailedCompileListener(event.Listener):
    """Releases the lock of a function whose compilation raised (nothing is saved then)."""

    def on_start(self, event_):
        pass

    def on_end(self, event_):
        # numba 0.68's Event.is_failed is True for a compilation that succeeded (it tests the
        # exception details for None, which they are then): read the details themselves.
        details = getattr(event_, "_exc_details", None)
        if details and details[0] is not None:
            cache = getattr(event_.data["dispatcher"], "_cache", None)
            file_lock.release(_COMPILING.pop(id(cache), None))
