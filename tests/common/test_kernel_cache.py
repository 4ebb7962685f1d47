"""Where numba caches the compiled kernels (harness/common/kernel_cache.py): a kernel changed in
another file than its caller is compiled again, never loaded stale; every global a kernel reads
is part of the fingerprint; old fingerprint folders are pruned."""

from __future__ import annotations

import ast
import importlib
import inspect
import json
import os
import shutil
import subprocess
import sys
import types
from pathlib import Path

import pytest
from numba.core import caching

from mbh._harness.common import file_lock, kernel_cache

ROOT = Path(__file__).resolve().parents[2]
#: Prints Φ of the four-bar at its reference coordinates: kernels.phi (kernels.py) inlines
#: bodykin._with_origin (bodykin.py), the function the test edits.
PHI_SCRIPT = """
import json
from mbh._adapters.inhouse.bodies import kernels
from mbh._adapters.inhouse.bodies.constraints import ConstraintSystem, reference_coordinates
from mbh._harness.model import scenario
mech = scenario.load("fourbar")
print(json.dumps(kernels.phi(reference_coordinates(mech), 0.0,
                             ConstraintSystem(mech).kernel_args).tolist()))
"""
ORIGINAL = "    return x + coordinates[k], y + coordinates[k + 1], z\n"
#: Every point of a (planar) body moves by 1 m in x; the ground's points stay.
EDITED = "    return x + coordinates[k] + 1.0, y + coordinates[k + 1], z\n"


def _copy_of_the_package(folder: Path) -> Path:
    """The package laid out as a wheel installs it (mbh/, mbh/_harness from harness/,
    mbh/_adapters from adapters/, the scenario files in mbh/_harness/scenarios) under ``folder``,
    without numba caches."""
    ignore = shutil.ignore_patterns("__pycache__")
    package = folder / "mbh"
    shutil.copytree(ROOT / "mbh", package, ignore=ignore)
    for source, mapped in (("harness", "_harness"), ("adapters", "_adapters")):
        shutil.copytree(ROOT / source, package / mapped, ignore=ignore)
    (package / "_harness" / "scenarios").mkdir()
    for scene in (ROOT / "scenarios").glob("*.toml"):
        shutil.copy(scene, package / "_harness" / "scenarios")
    return folder


def _phi(copy: Path, cache: Path, **extra) -> list[float]:
    env = {key: value for key, value in os.environ.items() if not key.startswith("NUMBA_")}
    env |= {"PYTHONPATH": str(copy), "MBH_CACHE_HOME": str(cache), **extra}
    done = subprocess.run([sys.executable, "-c", PHI_SCRIPT], cwd=copy, env=env,
                          capture_output=True, text=True, timeout=900, check=False)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.splitlines()[-1])


@pytest.mark.slow
def test_a_kernel_changed_in_another_file_than_its_caller_is_compiled_again(tmp_path):
    """Measured (2026-11-27, loaded 2-core machine): each of the four runs ~5 s cold, ~1.5 s
    warm; the test ~20 s."""
    copy, cache = _copy_of_the_package(tmp_path / "copy"), tmp_path / "cache"
    before = _phi(copy, cache)
    bodykin = copy / "mbh" / "_adapters" / "inhouse" / "bodies" / "bodykin.py"
    assert bodykin.read_text().count(ORIGINAL) == 1
    bodykin.write_text(bodykin.read_text().replace(ORIGINAL, EDITED))
    after = _phi(copy, cache)
    # A point row joining two bodies keeps its value; one joining a body and the ground moves by
    # exactly ±1 m (a difference of numbers ≤ 4 m: round-off 1e-15, bounded at 1e-12).
    changed = [a - b for a, b in zip(after, before, strict=True) if a != b]
    assert changed and all(abs(abs(d) - 1.0) < 1e-12 for d in changed), (before, after)
    assert len(list((cache / "numba").iterdir())) == 2  # a new fingerprint folder, the old kept
    # The control: numba's own placement (beside the source) loads kernels.phi's old binary,
    # since kernels.py did not change — the crash or wrong number the fingerprint prevents.
    in_tree = {"NUMBA_CACHE_LOCATOR_CLASSES": "InTreeCacheLocator"}
    bodykin.write_text(bodykin.read_text().replace(EDITED, ORIGINAL))
    assert _phi(copy, cache, **in_tree) == before
    bodykin.write_text(bodykin.read_text().replace(ORIGINAL, EDITED))
    assert _phi(copy, cache, **in_tree) == before  # stale


def _jitted(value) -> types.FunctionType | None:
    """The Python function of a numba dispatcher or cfunc, else None."""
    return getattr(value, "py_func", None) or getattr(value, "_pyfunc", None)


def _names_read(code: types.CodeType) -> set[str]:
    names = set(code.co_names)
    for constant in code.co_consts:
        if isinstance(constant, types.CodeType):
            names |= _names_read(constant)
    return names


def _imported_from(path: Path) -> dict[str, str]:
    """{name: module} of every ``from module import name`` in ``path``."""
    found = {}
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.module and not node.level:
            found |= {alias.asname or alias.name: node.module for alias in node.names}
    return found


def _project_file(module_name: str) -> Path | None:
    if module_name.split(".")[:2] not in (["mbh", "_harness"], ["mbh", "_adapters"]):
        return None
    return Path(inspect.getfile(importlib.import_module(module_name))).resolve()


def test_every_global_a_compiled_kernel_reads_is_in_the_fingerprint():
    """The fingerprint digests kernel_sources(): every jitted function of the kernel packages,
    every jitted function it calls and every project module or constant it reads must be there."""
    sources = set(kernel_cache.kernel_sources())
    kernels = {}
    for package in kernel_cache.KERNEL_PACKAGES:
        for path in sorted(package.rglob("*.py")):
            parts = path.relative_to(ROOT).with_suffix("").parts
            parts = parts[:-1] if parts[-1] == "__init__" else parts
            module = importlib.import_module("mbh._" + ".".join(parts))
            for value in vars(module).values():
                function = _jitted(value)
                if function is not None:
                    kernels[function.__qualname__, function.__module__] = function
    assert len(kernels) > 50
    missing = []
    for (name, module_name), function in sorted(kernels.items()):
        defined_in = Path(inspect.getfile(function)).resolve()
        if defined_in not in sources:
            missing.append(f"{module_name}.{name} is defined in {defined_in}")
        imports = _imported_from(defined_in)
        for read in _names_read(function.__code__) & set(function.__globals__):
            value = function.__globals__[read]
            if _jitted(value) is not None:
                origin = Path(inspect.getfile(_jitted(value))).resolve()
            elif isinstance(value, types.ModuleType):
                origin = _project_file(value.__name__)
            else:
                origin = _project_file(imports.get(read, module_name))
            if origin is not None and origin not in sources:
                missing.append(f"{module_name}.{name} reads {read} of {origin}")
    assert not missing, missing


def test_the_kernel_packages_are_cached_in_the_fingerprint_folder_and_the_rest_left_to_numba(
        tmp_path, monkeypatch):
    monkeypatch.setenv("MBH_GENERATED_DIR", str(tmp_path))
    source = kernel_cache.KERNEL_PACKAGES[0] / "bodies" / "kernels.py"
    assert kernel_cache.cache_folder(source).parent == kernel_cache.kernel_folder()
    assert kernel_cache.kernel_folder().name == kernel_cache.fingerprint(
        kernel_cache.kernel_sources())
    generated = tmp_path / "abc" / "mbh_1" / "mbh_1.py"
    assert kernel_cache.cache_folder(generated) == generated.parent / "__pycache__"
    assert kernel_cache.cache_folder(Path(caching.__file__)) is None
    assert caching.CacheImpl._locator_classes[0] is kernel_cache.KernelCacheLocator


def test_the_fingerprint_changes_with_any_byte_of_a_source(tmp_path, monkeypatch):
    monkeypatch.setattr(kernel_cache, "_ROOT", tmp_path)
    source = tmp_path / "kernel.py"
    source.write_text("x = 1\n")
    before = kernel_cache.fingerprint([source])
    source.write_text("x = 2\n")
    assert kernel_cache.fingerprint([source]) != before != kernel_cache.fingerprint()


def test_fingerprint_folders_beyond_the_ones_used_last_are_removed(tmp_path):
    for age, name in enumerate(["newest", "second", "third", "fourth", "fifth"]):
        (tmp_path / name).mkdir()
        (tmp_path / name / kernel_cache.LAST_USE).touch()
        os.utime(tmp_path / name / kernel_cache.LAST_USE, (1e9 - age, 1e9 - age))
    kernel_cache._prune(tmp_path)
    assert sorted(path.name for path in tmp_path.iterdir()) == sorted(
        ["newest", "second", "third"][:kernel_cache.KEEP])


#: Compiles (or loads) Φ of the four-bar and prints how numba got kernels.phi: {misses, hits}.
PHI_STATS_SCRIPT = PHI_SCRIPT + """
stats = kernels.phi.stats
print(json.dumps({"misses": sum(stats.cache_misses.values()),
                  "hits": sum(stats.cache_hits.values())}))
"""


def test_two_processes_compiling_one_kernel_compile_it_once(tmp_path):
    """Two processes start on an empty cache at once and both need kernels.phi: one compiles it
    under its lock, the other waits and loads it (numba counts a cache hit, not a miss).
    Measured (2026-11-29): ~6 s."""
    copy, cache = _copy_of_the_package(tmp_path / "copy"), tmp_path / "cache"
    env = {key: value for key, value in os.environ.items() if not key.startswith("NUMBA_")}
    env |= {"PYTHONPATH": str(copy), "MBH_CACHE_HOME": str(cache)}
    runs = [subprocess.Popen([sys.executable, "-c", PHI_STATS_SCRIPT], cwd=copy, env=env,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
            for _ in range(2)]
    outputs = [run.communicate(timeout=900) for run in runs]
    assert all(run.returncode == 0 for run in runs), [err for _, err in outputs]
    phis = [json.loads(out.splitlines()[-2]) for out, _ in outputs]
    stats = sorted((json.loads(out.splitlines()[-1])["misses"],
                    json.loads(out.splitlines()[-1])["hits"]) for out, _ in outputs)
    assert phis[0] == phis[1]
    assert stats == [(0, 1), (1, 0)], stats


def test_a_compilation_that_fails_releases_its_lock_and_one_that_succeeds_keeps_it(tmp_path):
    """The lock a cache miss took is kept until the save when the compilation succeeds, and
    released when it raises (nothing is saved then, and a waiting process must not wait for
    ever)."""
    cache = types.SimpleNamespace()
    dispatcher = types.SimpleNamespace(_cache=cache)
    listener = kernel_cache._FailedCompileListener()

    def end(details):
        event_ = types.SimpleNamespace(data={"dispatcher": dispatcher}, _exc_details=details)
        listener.on_end(event_)

    path = tmp_path / "kernel.lock"
    kernel_cache._COMPILING[id(cache)] = file_lock.acquire(path)
    end(None)  # succeeded: numba saves next, which releases
    assert path in file_lock._HELD
    end((TypeError, TypeError("no such type"), None))
    assert path not in file_lock._HELD and id(cache) not in kernel_cache._COMPILING
