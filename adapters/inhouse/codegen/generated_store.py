"""The folder of generated functions (:mod:`mbh._adapters.inhouse.codegen.generated`): one entry per traced
source, the whole folder bounded in size, a damaged entry rebuilt.

Layout, under :func:`mbh._harness.common.locations.generated_cache` (``$MBH_GENERATED_DIR``, else
``generated`` in the user cache)::

    <toolchain>/<name>/<name>.py     the source; <name> is made of its hash
    <toolchain>/<name>/__pycache__/  numba's cache of its compiled function (placed there by
                                     mbh._harness.common.kernel_cache), and the source's bytecode
    <toolchain>/<name>/used          present once compiled; modified at every load (last use)
    <toolchain>/<name>/lock          held by the process that compiles or loads the entry
    <toolchain>/<key>.trace          a remembered trace (:func:`remember`): which entry, or why
                                     none, the trace of inputs with digest <key> gave; modified
                                     at every read (last use)

``<toolchain>`` is :func:`mbh._harness.common.kernel_cache.fingerprint` of the Python, numba and
llvmlite versions and of the code that compiles a source
(:mod:`~mbh._adapters.inhouse.codegen.straight_line`): another numba, or another way of compiling,
finds no entry "compiled" that it would have to compile again.
The source's text depends on the kernels it was traced from, so a kernel change makes new names.

* **Bounded.** After every new compilation the least recently used entries of the folder (every
  toolchain; files of earlier layouts count as entries too) are removed until it holds at most
  :func:`max_bytes` (``$MBH_GENERATED_MAX_MB``, default :data:`DEFAULT_MAX_MB`).
* **Whole.** Every file is written under a temporary name, then renamed (numba does the same for
  its cache), so a concurrent reader never sees half a file.
* **Rebuilt.** A source whose text is not the one traced (cut short, garbled) is written again; an
  import that fails while numba's cache files are present is retried once without them (a cut or
  garbage index or data file), compiling the function again.
"""

from __future__ import annotations

import contextlib
import functools
import importlib.util
import json
import math
import os
import py_compile
import shutil
import sys
from pathlib import Path
from types import ModuleType

from mbh._adapters.inhouse.codegen import straight_line
from mbh._harness.common import file_lock, kernel_opt_level
from mbh._harness.common.errors import MbhError
from mbh._harness.common.kernel_cache import fingerprint
from mbh._harness.common.locations import generated_cache

#: Environment variable bounding the folder's size, in MB (10⁶ bytes).
MAX_MB_ENV = "MBH_GENERATED_MAX_MB"
#: The default bound, MB.  Measured (2026-11-26): a full test run (default and slow suites) from
#: an empty folder makes 52–54 entries, 26–28 MB (0.52 MB an entry).  A nightly campaign's
#: in-house formulations (11 scenes × 4 constraint treatments, 1–4 functions each) make ~90
#: entries, ~50 MB (estimated at that size).  500 MB keeps both several times over.
DEFAULT_MAX_MB = 500
#: The file marking an entry compiled; its modification time is the entry's last use.
USED = "used"
#: The lock file of an entry, held while it is compiled or loaded.
LOCK = "lock"


class GeneratedCacheSettingError(MbhError, ValueError):
    """``$MBH_GENERATED_MAX_MB`` is not a positive number."""


def max_bytes() -> int:
    """The folder's bound in bytes: ``$MBH_GENERATED_MAX_MB`` MB, else :data:`DEFAULT_MAX_MB`.

    Raises
    ------
    GeneratedCacheSettingError
        When the variable is set to anything but a positive number.
    """
    text = os.environ.get(MAX_MB_ENV, "").strip()
    if not text:
        return DEFAULT_MAX_MB * 10**6
    try:
        megabytes = float(text)
    except ValueError:
        megabytes = float("nan")
    if not (math.isfinite(megabytes) and megabytes > 0):
        raise GeneratedCacheSettingError(
            f"environment variable {MAX_MB_ENV}={text!r}: expected a positive number of MB")
    return int(megabytes * 10**6)


@functools.cache
def toolchain() -> str:
    """This toolchain's folder name (see the module notes)."""
    return fingerprint([Path(straight_line.__file__)])


def entry_folder(name: str) -> Path:
    """The folder of entry ``name`` for this toolchain."""
    return generated_cache() / toolchain() / name


def is_compiled(name: str) -> bool:
    """Whether entry ``name`` was compiled (by any process using this toolchain)."""
    return (entry_folder(name) / USED).exists()


def entry_source(name: str) -> str | None:
    """The source text stored in entry ``name``, or None (absent, unreadable)."""
    try:
        return (entry_folder(name) / f"{name}.py").read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return None


def _trace_path(key: str) -> Path:
    return generated_cache() / toolchain() / f"{key}.trace"


def remembered(key: str) -> dict | None:
    """The JSON object :func:`remember` stored under ``key``, marked used; None when there is
    none (never stored, evicted, unreadable, garbled)."""
    path = _trace_path(key)
    try:
        value = json.loads(path.read_text(encoding="utf-8"))
        os.utime(path)
    except (OSError, UnicodeDecodeError, ValueError):
        return None
    return value if isinstance(value, dict) else None


def remember(key: str, value: dict) -> None:
    """Store the JSON object ``value`` under ``key`` (written whole); a folder that cannot be
    written only loses the memo."""
    try:
        _write_whole(_trace_path(key), json.dumps(value, sort_keys=True).encode())
    except OSError:
        pass


def load(name: str, source: str, announce=None) -> ModuleType:
    """Module ``name`` of ``source`` (registered in :data:`sys.modules`, where numba's cache looks
    it up), its functions compiled or loaded from numba's cache.  A damaged entry is rebuilt; the
    entry is marked used, and after a new compilation the folder is bounded (:func:`evict`).
    One process compiles an entry while others that want it wait (:mod:`mbh._harness.common.file_lock`
    on the entry's :data:`LOCK`), then load it; ``announce``, a context manager, is entered around
    a compilation (an entry not marked :data:`USED`).

    Raises
    ------
    GeneratedCacheSettingError
        When ``$MBH_GENERATED_MAX_MB`` is not a positive number.
    Exception
        Whatever the import raises when the source does not compile, even without a cache.
    """
    limit = max_bytes()  # a bad setting is reported before anything is compiled
    entry = entry_folder(name)
    used = entry / USED
    with file_lock.held(entry / LOCK):
        compiled_now = not used.exists()
        with announce if compiled_now and announce is not None else contextlib.nullcontext():
            module = _import_entry(name, entry, source)
        try:
            used.touch()
        except OSError:  # removed meanwhile by another process's eviction: only the mark is lost
            pass
    if compiled_now:
        evict(generated_cache(), limit)
    return module


def _import_entry(name: str, entry: Path, source: str) -> ModuleType:
    """Write ``source`` into ``entry`` and import it as module ``name``, compiling its function or
    loading it from numba's cache; a damaged cache is removed and the import tried once more."""
    path = entry / f"{name}.py"
    _write_whole(path, source.encode())
    try:
        module = _import(name, path)
    except Exception:
        numba_cache = entry / "__pycache__"
        if not numba_cache.exists():
            raise
        shutil.rmtree(numba_cache, ignore_errors=True)
        module = _import(name, path)
    _keep_bytecode(path, source.encode())
    return module


def _keep_bytecode(path: Path, source: bytes) -> None:
    """Write the bytecode of ``path`` (holding ``source``) where Python looks for it, unless a
    valid one is there: a later import then skips compiling the long source (0.02–0.1 s an
    entry), even where Python writes no bytecode itself (``$PYTHONDONTWRITEBYTECODE``).  The file
    names the source by its hash (checked at every import), and is written whole; a folder that
    cannot be written only loses the saving."""
    bytecode = Path(importlib.util.cache_from_source(str(path)))
    try:
        with bytecode.open("rb") as file:
            header = file.read(16)  # magic, flags, source hash (PEP 552); not the code
    except OSError:
        header = b""
    if header == importlib.util.MAGIC_NUMBER + _CHECKED_HASH + importlib.util.source_hash(source):
        return
    try:
        py_compile.compile(str(path), doraise=True,
                           invalidation_mode=py_compile.PycInvalidationMode.CHECKED_HASH)
    except (OSError, py_compile.PyCompileError):
        pass


#: The flags word of a bytecode file checked against its source's hash (PEP 552).
_CHECKED_HASH = (0b11).to_bytes(4, "little")


def _write_whole(path: Path, content: bytes) -> None:
    """Make ``path`` hold ``content``: written under a temporary name and renamed, unless it
    holds it already."""
    try:
        if path.read_bytes() == content:
            return
    except OSError:  # not written yet
        pass
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(f"{path.name}.{os.getpid()}.tmp")
    partial.write_bytes(content)
    os.replace(partial, path)


def _import(name: str, path: Path) -> ModuleType:
    """Execute ``path`` as module ``name``, registered in :data:`sys.modules` while it runs and
    after (removed again when it raises); its function compiles at the kernels' LLVM level
    (:mod:`mbh._harness.common.kernel_opt_level`)."""
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        with kernel_opt_level.at_kernel_level():
            spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[name]
        raise
    return module


def evict(root: Path, limit: int) -> list[Path]:
    """Remove the least recently used entries of ``root`` until it holds at most ``limit``
    bytes; returns what was removed.  An entry is each item two levels down
    (``<toolchain>/<name>``) and each file directly in ``root``; its last use is the modification
    time of its :data:`USED` mark, else its own."""
    entries = []
    for path in _children(root):
        for entry in _children(path) if path.is_dir() else [path]:
            entries.append((_last_use(entry), _size(entry), entry))
    total = sum(size for _, size, _ in entries)
    removed = []
    for _, size, entry in sorted(entries):
        if total <= limit:
            break
        if entry.is_dir():
            shutil.rmtree(entry, ignore_errors=True)
        else:
            entry.unlink(missing_ok=True)
        total -= size
        removed.append(entry)
    return removed


def _children(folder: Path) -> list[Path]:
    try:
        return list(folder.iterdir())
    except OSError:  # removed meanwhile
        return []


def _last_use(entry: Path) -> float:
    for path in (entry / USED, entry):
        try:
            return path.stat().st_mtime
        except OSError:
            continue
    return 0.0


def _size(entry: Path) -> int:
    """Bytes of the file ``entry``, or of every file under the folder ``entry``."""
    total = 0
    for path in [entry, *entry.rglob("*")] if entry.is_dir() else [entry]:
        try:
            total += path.stat().st_size if path.is_file() else 0
        except OSError:
            continue
    return total
