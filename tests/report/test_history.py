"""The history's change points on synthetic histories of 30 runs with the measured noise
(tests/report/history_cases.py): a 20 % calibrated-time step and a 10× error step found at their
run, a single slow run and a one-run error-free jitter not flagged, a drift seen, status flips,
engine version changes named; then the page built from such a history and ``mbh history`` on
stored runs.

Every synthetic history uses a fixed seed; benchmarks/history_detection.py gives the rates over
100 random ones (docs/history.md).
"""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from mbh._harness.report.changepoints import ERROR, TIME, detect_steps, noise_level
from mbh._harness.report.history import (find_changes, load_history, open_regressions,
                                    version_changes)
from mbh._harness.report.history_page import build_history
from mbh._harness.report.history_figures import method_family
from mbh._harness.store.runs import RunStore
from tests.helpers import run_mbh
from tests.report.history_cases import case, history

RUNS = 30
TIME_STEP_RUN, ERROR_STEP_RUN, OUTLIER_RUN, UPGRADE_RUN, FAILING_FROM = 17, 12, 20, 15, 25


def _synthetic(seed: int = 30):
    """Seven cases over 30 runs: a time step, an error step, a one-run outlier, a status flip to
    the end, an engine upgrade with an error step, a drift, a one-run status blip."""
    rng = np.random.default_rng(seed)
    stepped_time = case(rng, RUNS, "rk4+direct")
    stepped_time.time[TIME_STEP_RUN:] *= 1.2
    stepped_error = case(rng, RUNS, "rk4+baumgarte")
    stepped_error.error[ERROR_STEP_RUN:] *= 10
    outlier = case(rng, RUNS, "rk4+none")
    outlier.time[OUTLIER_RUN] *= 3
    failing = case(rng, RUNS, "rk4+partition")
    failing.status = ["ok"] * FAILING_FROM + ["failed"] * (RUNS - FAILING_FROM)
    upgraded = case(rng, RUNS, "default", adapter="mujoco")
    upgraded.error[UPGRADE_RUN:] *= 4
    drifting = case(rng, RUNS, "best", adapter="mujoco")
    drifting.time *= 1.01 ** np.arange(RUNS)  # +1 % a run, ×1.33 over the history
    for engine_case in (upgraded, drifting):
        engine_case.version = ["3.1"] * UPGRADE_RUN + ["3.2"] * (RUNS - UPGRADE_RUN)
    blip = case(rng, RUNS, "rk4+direct", dt=1e-2)
    blip.status = ["ok"] * 10 + ["timeout"] + ["ok"] * (RUNS - 11)
    cases = [stepped_time, stepped_error, outlier, failing, upgraded, drifting, blip]
    return history(cases, RUNS), {c.method + f"@{c.dt:g}": c.case_id for c in cases}


@pytest.fixture(scope="module")
def synthetic():
    built, ids = _synthetic()
    return built, ids, find_changes(built)


def _of(changes, case_id, quantity=None):
    mine = changes[changes["case_id"] == case_id]
    return mine if quantity is None else mine[mine["quantity"] == quantity]


def test_a_20_percent_time_step_is_found_at_its_run(synthetic):
    _, ids, changes = synthetic
    found = _of(changes, ids["rk4+direct@0.001"])
    assert found[["quantity", "kind", "run"]].values.tolist() == [
        ["calibrated_time", "regression", TIME_STEP_RUN]]
    # Size: 1.2 within the noise of the segment medians (σ 0.036 per run, 13 runs after the step:
    # about ±0.015 on the log; measured 1.204 here).
    assert 1.15 < found["factor"].iloc[0] < 1.25
    assert found["confidence"].iloc[0] > 0.999 and bool(found["open"].iloc[0])


def test_a_10x_error_step_is_found_at_its_run_in_every_error(synthetic):
    _, ids, changes = synthetic
    found = _of(changes, ids["rk4+baumgarte@0.001"])
    assert set(found["quantity"]) == {"main_output_error", "max_constraint_violation",
                                      "max_energy_error_rel"}
    assert set(found["run"]) == {ERROR_STEP_RUN} and set(found["kind"]) == {"regression"}
    # 1 % jitter on each error: the ratio of medians is 10 within 1 % (measured 10.011).
    assert np.allclose(found["factor"], 10.0, rtol=0.01)


def test_a_single_slow_run_is_not_a_change(synthetic):
    _, ids, changes = synthetic
    assert _of(changes, ids["rk4+none@0.001"]).empty


def test_status_flips_count_at_their_first_run_and_first_in_the_list(synthetic):
    _, ids, changes = synthetic
    failing = _of(changes, ids["rk4+partition@0.001"], "status")
    assert failing[["kind", "run", "before", "after", "open"]].values.tolist() == [
        ["regression", FAILING_FROM, "ok", "failed", True]]
    blip = _of(changes, ids["rk4+direct@0.01"], "status")
    assert blip[["kind", "run", "open"]].values.tolist() == [["regression", 10, False],
                                                             ["improvement", 11, False]]
    # Status first, then the errors, then the time.
    order = changes["quantity"].map({"status": 0, "main_output_error": 1,
                                     "max_constraint_violation": 2, "max_energy_error_rel": 3,
                                     "calibrated_time": 4}).tolist()
    assert order == sorted(order)
    # The failing runs' values are left out of the numeric series: no error or time change.
    assert set(_of(changes, ids["rk4+partition@0.001"])["quantity"]) == {"status"}


def test_an_engine_upgrade_is_a_marker_and_names_the_change_at_its_run(synthetic):
    built, ids, changes = synthetic
    assert version_changes(built).values.tolist() == [[UPGRADE_RUN, "mujoco", "3.1", "3.2"]]
    found = _of(changes, ids["default@0.001"], "main_output_error")
    assert found[["run", "version_change"]].values.tolist() == [
        [UPGRADE_RUN, "mujoco 3.1 → 3.2"]]
    assert np.allclose(found["factor"], 4.0, rtol=0.01)


def test_a_drift_is_seen_as_steps_for_the_worse(synthetic):
    _, ids, changes = synthetic
    found = _of(changes, ids["best@0.001"])
    # +1 % a run: found as one step or more, all for the worse, together at least ×1.15 of the
    # ×1.33 (measured here: one step ×1.18 at run 20).
    assert len(found) >= 1 and set(found["kind"]) == {"regression"}
    assert set(found["quantity"]) == {"calibrated_time"}
    assert np.prod(found["factor"]) > 1.15


def test_a_regression_undone_later_is_not_open():
    rng = np.random.default_rng(7)
    fixed = case(rng, RUNS)
    fixed.error[10:20] *= 10
    changes = find_changes(history([fixed], RUNS))
    main = changes[changes["quantity"] == "main_output_error"]
    assert main[["kind", "run", "open"]].values.tolist() == [["regression", 10, False],
                                                            ["improvement", 20, False]]
    assert open_regressions(changes).empty


def test_noise_and_floors():
    # MAD of successive differences: a step of any size leaves it near the noise.
    rng = np.random.default_rng(3)
    logs = 0.1 * rng.standard_normal(200)
    stepped = logs + np.where(np.arange(200) >= 100, 5.0, 0.0)
    assert noise_level(logs) == pytest.approx(0.1, rel=0.15)  # 200 samples: ~7 % scatter
    assert noise_level(stepped) == pytest.approx(noise_level(logs), rel=0.05)
    assert noise_level(np.zeros(10), floor=0.01) == 0.01
    # Round-off-sized errors count as the floor: no step between 1e-16 and 1e-15.
    assert detect_steps(np.r_[np.full(10, 1e-16), np.full(10, 1e-15)], ERROR) == []
    assert detect_steps([1.0, 2.0, 3.0], TIME) == []  # fewer than two runs a segment
    with pytest.raises(ValueError, match="finite"):
        detect_steps([1.0, np.nan, 1.0], ERROR)


def test_method_families():
    assert [method_family(m) for m in ("rk4+direct", "ida:rtol=1e-6", "ida", "best",
                                       "default")] == ["rk4", "ida", "ida", "default & best",
                                                       "default & best"]


def test_page_marks_both_steps_and_links_the_first_run_report(synthetic, tmp_path):
    built, ids, changes = synthetic
    # A built report of the time step's first run, as mbh nightly leaves it.
    run_id = built.runs["run_id"].iloc[TIME_STEP_RUN]
    report = tmp_path / "results" / run_id / "report" / "report.html"
    report.parent.mkdir(parents=True)
    report.write_text("<html></html>")
    page = build_history(root=tmp_path / "results", out=tmp_path / "page", built_at="fixed",
                         history=built, changes=changes)
    html = page.read_text(encoding="utf-8")
    # Figures: fourbar · inhouse · rk4, fourbar · mujoco · default & best.
    assert html.count('<figure class="fig"') == 2
    assert "regression of calibrated wall time in rk4+direct dt=0.001 at run 17" in html
    assert "regression of main-output error in rk4+baumgarte dt=0.001 at run 12" in html
    assert f'<a href="../results/{run_id}/report/report.html">{run_id}</a>' in html
    rows = re.findall(r"<tr>\s*<td class=\"(regression|improvement)\">", html)
    assert len(rows) == len(changes)
    assert "mujoco 3.1 → 3.2" in html


def _store_runs(root, errors: list[float]) -> list[str]:
    """Runs of campaign ``tiny`` with one case each, whose main-output error is ``errors[i]``."""

    class Campaign:
        name, path, cases, sweep, text = "tiny", "tiny.toml", (), None, ""

    ids = []
    for error in errors:
        store = RunStore.create(Campaign(), root)
        store.add({"case_id": "fourbar|inhouse|rk4+direct|0.001|1.0", "scenario": "fourbar",
                   "adapter": "inhouse", "adapter_version": "0.1", "method": "rk4+direct",
                   "dt": 1e-3, "status": "ok", "main_output_error": error,
                   "max_constraint_violation": 1e-9, "max_energy_error_rel": 1e-9,
                   "wall_time_s": 0.01}, None)
        store.set_calibration(0.02)
        store.finish("complete")
        ids.append(store.run_id)
    return ids


def test_mbh_history_on_stored_runs(tmp_path):
    root = tmp_path / "results"
    ids = _store_runs(root, [1e-8, 1e-8, 1e-6])
    assert load_history("tiny", root).runs["run_id"].tolist() == ids
    status, stdout, stderr = run_mbh("history", "--root", str(root), "--out",
                                     str(tmp_path / "out"), "--json")
    assert status == 0, stderr
    document = json.loads(stdout)
    assert document["campaign"] == "tiny" and len(document["runs"]) == 3
    assert [(c["quantity"], c["kind"], c["run_id"]) for c in document["changes"]] == [
        ("main_output_error", "regression", ids[2])]
    assert document["runs"][0]["calibration_s"] == 0.02
    assert (tmp_path / "out" / "history.html").is_file()
    status, _, stderr = run_mbh("history", "--campaign", "nightly", "--root", str(root))
    assert status == 2 and "no finished run of campaign 'nightly'" in stderr \
        and "campaigns stored: tiny" in stderr


def test_calibrated_times_are_kept_only_for_runs_measured_by_the_newest_runs_workload(tmp_path):
    root = tmp_path / "results"
    ids = _store_runs(root, [1e-8, 1e-8, 1e-8])
    RunStore.open(ids[0], root).set_calibration(0.02, "solve_ivp+lu/1 numpy 1.0 scipy 1.0")
    history = load_history("tiny", root)
    assert np.isnan(history.runs["calibration_s"][0])
    assert history.runs["calibration_s"][1:].tolist() == [0.02, 0.02]
    assert np.isnan(history.cases["calibrated_time"][0])
    assert history.cases["calibrated_time"][1:].tolist() == pytest.approx([0.5, 0.5])
