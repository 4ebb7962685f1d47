"""The reference cache: atomic writes a process pool can share, metadata checked on load."""

from __future__ import annotations

import json
import multiprocessing
from pathlib import Path

import numpy as np
import pytest

from mbh._harness.model import scenario
from mbh._harness.model.timegrid import GRID_STEP
from mbh._harness.references.build import load_or_build, routes
from mbh._harness.store.reference_files import (ARRAYS, REFERENCE_VERSION, read_reference,
                                           reference_paths, stale_reason, stored_reference)

SHIPPED = ("fourbar", "fourbar_spatial", "slider_crank", "slider_crank_planar")
#: A four-bar of 20 ms: a reference build takes ~2 s (measured), enough to overlap builds.
TINY = ("duration = 4.0", "duration = 0.02")


@pytest.fixture
def tiny(tmp_path, monkeypatch, write_scenario):
    """The 20 ms four-bar, with MBH_CACHE_DIR pointing at an empty temporary directory."""
    cache = tmp_path / "cache"
    monkeypatch.setenv("MBH_CACHE_DIR", str(cache))
    text = scenario.scenario_path("fourbar").read_text()
    assert TINY[0] in text
    return scenario.load(write_scenario("fourbar", text.replace(*TINY))), cache


def _build_in_child(path: str, cache: str) -> str:
    """Load the scenario and its reference in a fresh process: digests of the data file and of
    the returned arrays, and the sample count."""
    import hashlib
    import os

    os.environ["MBH_CACHE_DIR"] = cache
    from mbh._harness.model import scenario as child_scenario
    from mbh._harness.references.build import load_or_build as child_load
    from mbh._harness.store.reference_files import reference_paths as child_paths

    mech = child_scenario.load(path)
    trajectory, _ = child_load(mech)
    data_path, _ = child_paths(mech)
    arrays = hashlib.sha256(trajectory.position.tobytes() + trajectory.velocity.tobytes())
    data = hashlib.sha256(data_path.read_bytes())
    return f"{data.hexdigest()} {arrays.hexdigest()} {trajectory.n_samples}"


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_references_pass_the_metadata_check(name):
    mech = scenario.load(name)
    cached = read_reference(mech, routes(mech))
    assert cached is not None, f"{name}: shipped reference rejected"
    assert stale_reason(mech, *reversed(cached), routes(mech)) == ""
    np.testing.assert_array_equal(stored_reference(mech).position, cached[0].position)


def test_processes_building_the_same_reference_at_once_share_one_file(tiny, tmp_path):
    mech, cache = tiny
    context = multiprocessing.get_context("spawn")
    with context.Pool(3) as pool:
        digests = pool.starmap(_build_in_child, [(str(tmp_path / "fourbar.toml"), str(cache))] * 3)
    data_path, info_path = reference_paths(mech)
    assert len(set(digests)) == 1 and digests[0].endswith(" 21")
    assert sorted(p.name for p in cache.iterdir()) == sorted([data_path.name, info_path.name])
    trajectory, info = load_or_build(mech)  # the shared file passes the check: no rebuild
    assert info["content_hash"] == mech.content_hash and trajectory.n_samples == 21


@pytest.mark.parametrize("edit, reason", [
    (lambda info: info.update(version=REFERENCE_VERSION - 1), "version"),
    (lambda info: info.update(grid_step=2 * GRID_STEP), "grid_step"),
    (lambda info: info.update(route_b=["rk4+none", 1e-3]), "routes"),
    (lambda info: info.update(scenario="other"), "scenario"),
    (lambda info: info["agreement"].update(max=1.0), "agreement"),
])
def test_metadata_mismatch_is_detected_and_rebuilt(tiny, edit, reason):
    mech, _ = tiny
    trajectory, info = load_or_build(mech)
    data_path, info_path = reference_paths(mech)
    stored = json.loads(info_path.read_text())
    edit(stored)
    info_path.write_text(json.dumps(stored))
    assert reason in stale_reason(mech, stored, trajectory, routes(mech))
    rebuilt, rebuilt_info = load_or_build(mech)
    stored_now = json.loads(info_path.read_text())
    assert stored_now["agreement"] == rebuilt_info["agreement"] == info["agreement"]
    assert stale_reason(mech, stored_now, rebuilt, routes(mech)) == ""
    np.testing.assert_array_equal(rebuilt.position, trajectory.position)


def test_a_report_reads_a_stored_reference_and_never_builds_one(tiny):
    mech, cache = tiny
    assert stored_reference(mech) is None and not cache.exists()
    trajectory, _ = load_or_build(mech)
    np.testing.assert_array_equal(stored_reference(mech).position, trajectory.position)


def test_arrays_off_the_grid_or_a_broken_file_rebuild(tiny):
    mech, _ = tiny
    trajectory, info = load_or_build(mech)
    data_path, info_path = reference_paths(mech)
    np.savez_compressed(data_path, times=trajectory.times[:-1], position=trajectory.position[:-1],
                        quaternion=trajectory.quaternion[:-1], velocity=trajectory.velocity[:-1],
                        angular_velocity=trajectory.angular_velocity[:-1])
    assert "shape" in stale_reason(mech, info, _read_cache_unchecked(data_path))
    assert load_or_build(mech)[0].n_samples == 21
    data_path.write_bytes(b"not a zip file")
    assert load_or_build(mech)[0].n_samples == 21


def _read_cache_unchecked(data_path: Path):
    from mbh._harness.model.trajectory import Trajectory

    with np.load(data_path) as data:
        return Trajectory(**{key: data[key] for key in ARRAYS})
