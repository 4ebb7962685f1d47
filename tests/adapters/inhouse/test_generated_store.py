"""The folder of generated functions (adapters/inhouse/codegen/generated_store.py): a damaged entry is
rebuilt, never fatal; the folder stays under its bound, the least recently used entries going
first; the bound's setting is checked."""

from __future__ import annotations

import importlib.util
import os
import sys
import uuid
from pathlib import Path

import numpy as np
import pytest

from mbh._adapters.inhouse.codegen import generated_store

#: A generated module as adapters/inhouse/codegen/generated.py writes one, compiled in ~1 s.
SOURCE = ("import numpy as np\nfrom numba import cfunc\n\n"
          "from mbh._adapters.inhouse.codegen.generated import SIGNATURE\n\n\n"
          "@cfunc(SIGNATURE, cache=True)\n"
          "def acceleration(q, v, t, out):\n    out[0] = 2.0 * q[0] + v[0] + t\n    return 1\n")


@pytest.fixture
def store(tmp_path, monkeypatch):
    monkeypatch.setenv("MBH_GENERATED_DIR", str(tmp_path))
    monkeypatch.delenv(generated_store.MAX_MB_ENV, raising=False)
    return tmp_path


def _fresh_load(name: str):
    """Load entry ``name`` as a new process would (nothing of it in sys.modules)."""
    sys.modules.pop(name, None)
    return generated_store.load(name, SOURCE).acceleration


def _result(function) -> float:
    out = np.zeros(1)
    assert function(np.array([1.0]), np.array([0.5]), 0.25, out) == 1
    return out[0]


def _numba_files(name: str) -> list:
    return sorted((generated_store.entry_folder(name) / "__pycache__").glob("*.nb[ic]"))


def test_an_entry_is_compiled_once_then_loaded(store):
    name = f"mbh_test_{uuid.uuid4().hex}"
    assert not generated_store.is_compiled(name)
    assert _result(_fresh_load(name)) == 2.75
    assert generated_store.is_compiled(name) and len(_numba_files(name)) == 2  # index, data
    written = {path: path.stat().st_mtime_ns for path in _numba_files(name)}
    assert _result(_fresh_load(name)) == 2.75
    assert {path: path.stat().st_mtime_ns for path in _numba_files(name)} == written  # loaded


def test_an_entry_keeps_its_bytecode_even_where_python_writes_none(store, monkeypatch):
    """A long source is compiled to bytecode once, not at every import."""
    monkeypatch.setattr(sys, "dont_write_bytecode", True)
    name = f"mbh_test_{uuid.uuid4().hex}"
    _fresh_load(name)
    bytecode = _bytecode(name)
    written = bytecode.stat().st_mtime_ns
    assert _result(_fresh_load(name)) == 2.75
    assert bytecode.stat().st_mtime_ns == written


def _bytecode(name: str):
    return Path(importlib.util.cache_from_source(
        str(generated_store.entry_folder(name) / f"{name}.py")))


@pytest.mark.parametrize("damage", ["source cut short", "source garbled", "index garbage",
                                    "data garbage", "index cut short", "data emptied",
                                    "bytecode garbage", "bytecode cut short"])
def test_a_damaged_entry_is_rebuilt(store, damage):
    name = f"mbh_test_{uuid.uuid4().hex}"
    _fresh_load(name)
    source = generated_store.entry_folder(name) / f"{name}.py"
    index, data = (next(path for path in _numba_files(name) if path.suffix == suffix)
                   for suffix in (".nbi", ".nbc"))
    good_bytecode = _bytecode(name).read_bytes()
    target, content = {
        "source cut short": (source, SOURCE.encode()[:len(SOURCE) // 2]),
        "source garbled": (source, b"\xff\xfe" + SOURCE.encode()[2:]),
        "index garbage": (index, os.urandom(300)),
        "data garbage": (data, os.urandom(3000)),
        "index cut short": (index, index.read_bytes()[:40]),
        "data emptied": (data, b""),
        "bytecode garbage": (_bytecode(name), os.urandom(500)),
        "bytecode cut short": (_bytecode(name), _bytecode(name).read_bytes()[:30]),
    }[damage]
    target.write_bytes(content)
    assert _result(_fresh_load(name)) == 2.75
    assert source.read_text() == SOURCE and len(_numba_files(name)) == 2
    assert _bytecode(name).read_bytes() == good_bytecode


def test_a_half_written_file_of_another_process_is_ignored(store):
    """What a process killed mid-write leaves: its temporary file; the entry is made whole."""
    name = f"mbh_test_{uuid.uuid4().hex}"
    entry = generated_store.entry_folder(name)
    entry.mkdir(parents=True)
    (entry / f"{name}.py.12345.tmp").write_text(SOURCE[:50])
    assert _result(_fresh_load(name)) == 2.75


def _entry(root, toolchain: str, name: str, size: int, last_use: float | None):
    folder = root / toolchain / name
    folder.mkdir(parents=True)
    (folder / f"{name}.py").write_bytes(b"x" * size)
    if last_use is not None:
        (folder / generated_store.USED).touch()
        os.utime(folder / generated_store.USED, (last_use, last_use))
    os.utime(folder, (1e9, 1e9))
    return folder


def test_eviction_keeps_the_folder_under_its_bound_removing_the_least_recently_used(tmp_path):
    uses = {"a": 1e9 + 5, "b": 1e9 + 1, "c": 1e9 + 3, "d": 1e9 + 4}
    for name, last_use in uses.items():
        _entry(tmp_path, "toolchain1", name, 1000, last_use)
    uncompiled = _entry(tmp_path, "toolchain2", "e", 1000, None)  # folder time 1e9: oldest
    old_layout = tmp_path / "mbh_0123.py"  # a file of the flat layout before toolchains
    old_layout.write_bytes(b"x" * 1000)
    os.utime(old_layout, (1e9 + 2, 1e9 + 2))
    removed = generated_store.evict(tmp_path, 3000)
    assert removed == [uncompiled, tmp_path / "toolchain1" / "b", old_layout]
    assert sorted(path.name for path in (tmp_path / "toolchain1").iterdir()) == ["a", "c", "d"]
    assert sum(path.stat().st_size for path in tmp_path.rglob("*") if path.is_file()) <= 3000
    assert generated_store.evict(tmp_path, 3000) == []


def test_a_new_compilation_bounds_the_folder(store, monkeypatch):
    first, second = (f"mbh_test_{uuid.uuid4().hex}" for _ in range(2))
    _fresh_load(first)
    os.utime(generated_store.entry_folder(first) / generated_store.USED, (1e9, 1e9))
    entry_bytes = sum(path.stat().st_size for path in store.rglob("*") if path.is_file())
    monkeypatch.setenv(generated_store.MAX_MB_ENV, str(1.5 * entry_bytes / 1e6))
    _fresh_load(second)
    assert not generated_store.entry_folder(first).exists()
    assert generated_store.is_compiled(second)


@pytest.mark.parametrize("setting", ["0", "-5", "lots", "nan", "inf"])
def test_a_bad_bound_is_refused_naming_the_variable(store, monkeypatch, setting):
    monkeypatch.setenv(generated_store.MAX_MB_ENV, setting)
    with pytest.raises(generated_store.GeneratedCacheSettingError, match="MBH_GENERATED_MAX_MB"):
        generated_store.load(f"mbh_test_{uuid.uuid4().hex}", SOURCE)
    assert not list(store.rglob("*.py"))  # refused before anything was written


def test_the_bound_is_read_in_megabytes(monkeypatch):
    monkeypatch.setenv(generated_store.MAX_MB_ENV, "2.5")
    assert generated_store.max_bytes() == 2_500_000
    monkeypatch.delenv(generated_store.MAX_MB_ENV)
    assert generated_store.max_bytes() == generated_store.DEFAULT_MAX_MB * 10**6
