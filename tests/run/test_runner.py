"""Campaign runs end to end (mbh._harness.run.campaign, mbh._harness.run.sweep, ``mbh run/runs/show/compare``):
the same rows through the process pool and a Dask LocalCluster, and from warm and cold workers,
failures as rows, Ctrl-C and resume, a diverging method, a bad campaign file refused before
anything runs, the stability sweep's bisection."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from mbh._adapters import adapter_names
from mbh._harness.common import environment
from mbh._harness.run.spec import load_campaign
from mbh._harness.run.campaign import run_campaign
from mbh._harness.run.row import CaseWork
from mbh._harness.model.timegrid import EVALUATION_STEP
from mbh._harness.store.manifest import list_runs
from mbh._harness.store.runs import RunStore
from mbh._harness.run.sweep import Bisection, stability_sweep
from mbh._harness.measure.verdict import Bounds

MBH = [sys.executable, "-m", "mbh._harness.cli"]

#: Row columns that hold wall-clock times (they differ between any two runs) or where the run
#: stored the case.
TIMING_COLUMNS = ["wall_time_s", "wall_time_per_sim_s", "wall_time_per_step_s", "wall_times_s",
                  "run_id", "trajectory_file"]

TINY = """
repetitions = 1
timeout_s = 120.0
accuracy = 1e-3

[t_end]
"*" = 0.2

[[group]]
scenarios = ["fourbar", "slider_crank_planar"]
adapters = ["inhouse", "mujoco"]
methods = ["best"]
dts = [1e-2]
"""

#: rk4+baumgarte is SIGKILLed mid-case and rkn4+direct sleeps past its 6 s limit (test work
#: below); euler+baumgarte with α = β = 1000 s⁻¹ at 10 ms diverges: the constraint error obeys
#: Φ̈ = −2αΦ̇ − β²Φ, a double eigenvalue λ = −1000 s⁻¹, and explicit Euler multiplies it by
#: |1 + Δt·λ| = 9 per step.
MISBEHAVING = """
timeout_s = 120.0
accuracy = 1e-5
calibration = false

[t_end]
"*" = 0.5

[[group]]
scenarios = ["fourbar"]
methods = { inhouse = ["rk4+direct", "rk4+baumgarte", "euler+baumgarte:alpha=1000,beta=1000"] }
dts = [1e-2]

[[group]]
scenarios = ["fourbar"]
methods = { inhouse = ["rkn4+direct"] }
dts = [1e-2]
timeout_s = 6.0

[sweep]
scenarios = ["fourbar"]
adapters = ["inhouse"]
methods = ["rk4+none"]
dt_min = 1e-3
dt_max = 1e-2
max_bisections = 3
"""


@dataclass(frozen=True)
class MisbehavingWork(CaseWork):
    """The campaign's work, except that one method's worker is SIGKILLed during its case and
    another's case hangs; test-only (adapters have no such switch)."""

    kill_method: str = ""
    hang_method: str = ""

    def __call__(self, spec):
        if spec.method == self.kill_method:
            threading.Timer(0.2, os.kill, (os.getpid(), signal.SIGKILL)).start()
        if spec.method in (self.kill_method, self.hang_method):
            super().__call__(spec)
            time.sleep(600)  # the kill (or the timeout) always lands before a result
        return super().__call__(spec)


def write_campaign(folder: Path, name: str, text: str) -> Path:
    path = folder / f"{name}.toml"
    path.write_text(text)
    return path


@pytest.fixture
def results(tmp_path, monkeypatch) -> Path:
    root = tmp_path / "results"
    monkeypatch.setenv("MBH_RESULTS_DIR", str(root))
    return root


def metric_rows(store: RunStore) -> pd.DataFrame:
    """The run's rows without the columns that differ between runs, in case order, and whether
    a trajectory was stored."""
    cases = store.cases()
    return cases.assign(trajectory_stored=cases["trajectory_file"].notna()) \
        .drop(columns=TIMING_COLUMNS).sort_values("case_id").reset_index(drop=True)


def assert_pool_and_dask_agree(campaign) -> pd.DataFrame:
    """Run ``campaign`` through the local pool (with calibration) and a Dask LocalCluster on
    loopback (without); the metric rows, sweep rows and trajectories must be identical."""
    distributed = pytest.importorskip("distributed")
    pool = run_campaign(campaign, workers=2, quiet=True)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  host="127.0.0.1", dashboard_address=":0") as cluster:
        dask = run_campaign(replace(campaign, calibration=False),
                            scheduler=cluster.scheduler_address, quiet=True)
    rows = metric_rows(pool)
    assert sorted(rows["case_id"]) == sorted(c.case_id for c in campaign.cases)
    # The same code on the same machine in fresh processes: identical, bit for bit.
    pd.testing.assert_frame_equal(rows, metric_rows(dask), check_exact=True)
    pd.testing.assert_frame_equal(pool.sweeps().drop(columns="run_id"),
                                  dask.sweeps().drop(columns="run_id"), check_exact=True)
    for case_id in rows.loc[rows["trajectory_stored"], "case_id"]:
        a, b = pool.trajectory(case_id), dask.trajectory(case_id)
        np.testing.assert_array_equal(a.position, b.position)
        np.testing.assert_array_equal(a.quaternion, b.quaternion)
    assert pool.manifest["status"] == dask.manifest["status"] == "complete"
    assert pool.calibration_s > 0 and dask.calibration_s is None
    return rows


def test_pool_and_dask_local_cluster_give_the_same_rows(tmp_path, results):
    campaign = load_campaign(write_campaign(tmp_path, "tiny", TINY))
    rows = assert_pool_and_dask_agree(campaign)
    assert len(rows) == 4
    assert (rows["status"] == "ok").all()  # every engine's best method on verified scenes
    assert (rows["reference"] == "verified").all()


@pytest.mark.slow
def test_smoke_campaign_gives_the_same_rows_through_pool_and_dask(results):
    rows = assert_pool_and_dask_agree(load_campaign("smoke"))
    assert set(rows["adapter"]) == set(adapter_names())


#: Run in a fresh interpreter, so that the warm template is started for this campaign (and keeps
#: its scenarios and references), not one an earlier test started: the campaign warm, then cold,
#: each into its own results root; prints both run ids.
WARM_AND_COLD = """
import sys
from mbh._harness.run.campaign import run_campaign
from mbh._harness.run.spec import load_campaign

campaign = load_campaign(sys.argv[1])
warm = run_campaign(campaign, workers=2, root=sys.argv[2], quiet=True)
cold = run_campaign(campaign, workers=2, root=sys.argv[3], quiet=True, warm_workers=False)
print(warm.run_id, cold.run_id)
"""


def test_warm_and_cold_workers_store_the_same_rows(tmp_path):
    """Cases forked from the template (which read their scenarios and references once) store
    what fresh interpreters store; bricard on Exudyn fails, so its reason is labelled from the
    reference's conditioning."""
    text = TINY.replace('"slider_crank_planar"', '"bricard"').replace('"mujoco"', '"exudyn"')
    path = write_campaign(tmp_path, "tiny", text)
    done = subprocess.run([sys.executable, "-c", WARM_AND_COLD, str(path), str(tmp_path / "warm"),
                           str(tmp_path / "cold")], capture_output=True, text=True, check=True)
    warm, cold = (RunStore.open(run_id, tmp_path / root)
                  for run_id, root in zip(done.stdout.split(), ("warm", "cold")))
    assert "warm workers unavailable" not in done.stderr  # the first run forked its cases
    rows = metric_rows(warm)
    assert len(rows) == 4 and (rows["status"] == "ok").any() and (rows["status"] != "ok").any()
    # The same code on the same machine, forked or fresh: identical, bit for bit.
    pd.testing.assert_frame_equal(rows, metric_rows(cold), check_exact=True)


def test_failures_become_rows_and_the_campaign_completes(tmp_path, results):
    campaign = load_campaign(write_campaign(tmp_path, "misbehaving", MISBEHAVING))
    work = MisbehavingWork(campaign.bounds, campaign.accuracy, kill_method="rk4+baumgarte",
                           hang_method="rkn4+direct")
    store = run_campaign(campaign, workers=2, quiet=True, work=work)
    rows = store.cases().set_index("method")
    assert store.manifest["status"] == "complete"
    assert rows.loc["rk4+direct", "status"] == "ok"
    assert rows.loc["rk4+baumgarte", "status"] == "crashed"
    assert rows.loc["rk4+baumgarte", "reason"].startswith("worker process killed by SIGKILL")
    assert rows.loc["rkn4+direct", "status"] == "timeout"
    assert "timeout of 6 s" in rows.loc["rkn4+direct", "reason"]
    diverging = rows.loc["euler+baumgarte:alpha=1000,beta=1000"]
    assert diverging["status"] == "diverged"
    # Measured with `mbh simulate fourbar --method euler+baumgarte:alpha=1000,beta=1000 --dt 0.01`:
    # the state norm passes 1e8 after t = 0.11 s; growing ×9 per step, round-off cannot move
    # the crossing by a step.
    assert diverging["failure_time"] == pytest.approx(0.11, abs=1e-9)
    check_sweep_row(store.sweeps(), campaign)


def check_sweep_row(sweeps: pd.DataFrame, campaign) -> None:
    """The stored sweep row is consistent: admissible steps only, passing ones all below the
    failing ones, and the answer the largest passing step tried."""
    assert len(sweeps) == 1
    row = sweeps.iloc[0]
    tried = json.loads(row["tried"])
    for dt, _status, _error in tried:
        k = EVALUATION_STEP / dt
        assert k == pytest.approx(round(k), rel=1e-12)
        assert campaign.sweep.dt_min - 1e-15 <= dt <= campaign.sweep.dt_max + 1e-15
    passing = [dt for dt, status, error in tried
               if status == "ok" and float(error) <= campaign.accuracy]
    failing = [dt for dt, status, error in tried if dt not in passing]
    # Measured (fourbar, rk4+none, 0.5 s): main-output error 1.15e-5 at dt 0.01 (fails the
    # 1e-5 accuracy), 6.95e-7 at 0.005, 1.07e-9 at 0.001 (pass); errors scale as dt^4, so the
    # bound stays inside [dt_min, dt_max] on any CPU.
    assert passing and failing
    assert max(passing) < min(failing)
    assert row["largest_stable_dt"] == max(passing)


@pytest.mark.parametrize("threshold_k, expected_k, bisections", [
    (7, 7, 10),     # the bracket closes on k = 7 exactly
    (1, 1, 10),     # dt_max already passes: one run
    (101, None, 10),  # nothing in range passes
    (7, 100, 0),    # no bisection allowed: only dt_max and dt_min are tried
])
def test_bisection_finds_the_largest_passing_step(threshold_k, expected_k, bisections):
    search = Bisection("fourbar", "inhouse", "rk4+none", 1, 100, bisections)

    @dataclass(frozen=True)
    class Spec:
        dt: float

        @property
        def case_id(self):
            return repr(self.dt)

    def run(specs):  # passes exactly for dt <= 0.01 / threshold_k
        return {spec.case_id: {"status": "ok" if round(EVALUATION_STEP / spec.dt) >= threshold_k
                               else "diverged", "accurate": True} for spec in specs}

    rows = []
    stability_sweep([search], lambda *key: Spec(key[-1]), run, rows.append)
    (row,) = rows
    if expected_k is None:
        assert math.isnan(row["largest_stable_dt"])
    else:
        assert row["largest_stable_dt"] == EVALUATION_STEP / expected_k
    assert len(json.loads(row["tried"])) <= 2 + bisections


@dataclass(frozen=True)
class MustNotRun:
    """Work for a run whose every case must come from the cache."""

    def __call__(self, spec):
        raise RuntimeError(f"{spec.case_id} ran although an identical case was cached")


def test_reuse_copies_identical_cases_instead_of_running_them(tmp_path, results):
    campaign = load_campaign(write_campaign(tmp_path, "tiny", TINY))
    campaign = replace(campaign, cases=campaign.cases[:2], calibration=False)
    first = run_campaign(campaign, workers=2, quiet=True)
    again = run_campaign(campaign, workers=2, quiet=True, reuse=True, work=MustNotRun())
    reused = again.cases()
    assert (reused["reused_from"] == first.run_id).all()
    pd.testing.assert_frame_equal(metric_rows(first),
                                  metric_rows(again).drop(columns="reused_from"),
                                  check_exact=True)


@pytest.mark.parametrize("change", [{"accuracy": 1e-9}, {"bounds": Bounds(gap=1e-2)}])
def test_reuse_takes_no_case_judged_under_other_settings(tmp_path, results, change):
    """A cached row's status and ``accurate`` flag were judged under its campaign's bounds and
    accuracy; a campaign with others must run the case again."""
    campaign = load_campaign(write_campaign(tmp_path, "tiny", TINY))
    campaign = replace(campaign, cases=campaign.cases[:1], calibration=False)
    run_campaign(campaign, workers=1, quiet=True)
    again = run_campaign(replace(campaign, **change), workers=1, quiet=True, reuse=True)
    reused = again.cases().get("reused_from")
    assert reused is None or reused.isna().all()


def test_the_code_fingerprint_follows_the_sources(tmp_path, monkeypatch):
    """Any edit of a computing package's file changes the fingerprint (so no cached row
    outlives the code that computed it)."""
    for package in environment.COMPUTING_PACKAGES:
        (tmp_path / package).mkdir()
        (tmp_path / package / "module.py").write_text("x = 1\n")
    monkeypatch.setattr(environment, "_REPO", tmp_path)
    before = environment.code_fingerprint()
    assert environment.code_fingerprint() == before
    (tmp_path / environment.COMPUTING_PACKAGES[-1] / "module.py").write_text("x = 2\n")
    assert environment.code_fingerprint() != before


def mbh(*args, root: Path, **options) -> subprocess.CompletedProcess:
    return subprocess.run([*MBH, *args], capture_output=True, text=True, timeout=600,
                          env=os.environ | {"MBH_RESULTS_DIR": str(root)}, **options)


#: 24 cases of 4 s at small steps: several seconds on one warm worker, so a second writer or a
#: signal arrives while cases are left (a warm worker starts a case in ~0.05 s).
INTERRUPTIBLE = """
timeout_s = 120.0
calibration = false

[[group]]
scenarios = ["fourbar"]
methods = { inhouse = ["rk4+direct", "rk4+none", "rkn4+direct", "rk4+baumgarte", "heun+direct",
                       "heun+none"] }
dts = [1e-3, 5e-4, 2e-4, 1e-4]
"""


def stored_parts(root: Path) -> list[Path]:
    return sorted(root.glob("*/cases/part-*.parquet"))


def start_run(path: Path, results: Path) -> subprocess.Popen:
    """``mbh run`` on the campaign at ``path`` in the background, returned once it has stored a
    case (or ended)."""
    # A shell that starts a job in the background (`.ci/run &`) ignores SIGINT in it, and the
    # child would inherit that: give it the default disposition, as an interactive run has.
    run = subprocess.Popen([*MBH, "run", str(path), "--workers", "1", "--quiet"],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                           env=os.environ | {"MBH_RESULTS_DIR": str(results)},
                           preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    for _ in range(6000):  # up to 10 min: a cold first case compiles the in-house kernels
        if stored_parts(results) or run.poll() is not None:
            break
        time.sleep(0.1)
    return run


def interrupt_and_resume(path: Path, results: Path, signum: int) -> dict:
    """Start ``mbh run`` on the campaign at ``path``, send ``signum`` once a case is stored, and
    check the run stopped with 128 + signum, marked ``interrupted`` with its finished cases
    kept; then ``--resume`` it and check it completes with every case stored exactly once.
    Returns the run's manifest."""
    ids = {case.case_id for case in load_campaign(path).cases}
    run = start_run(path, results)
    run.send_signal(signum)
    _, err = run.communicate(timeout=120)
    assert run.returncode == 128 + signum, err
    (manifest,) = list_runs(results)
    assert manifest["status"] == "interrupted"
    first = RunStore.open(manifest["run_id"], results).cases()
    assert 1 <= len(first) < len(ids)
    assert f"--resume {manifest['run_id']}" in err

    done = mbh("run", str(path), "--resume", manifest["run_id"], "--quiet", root=results)
    assert done.returncode == 0, done.stderr
    assert manifest["run_id"] in done.stdout
    store = RunStore.open(manifest["run_id"], results)
    assert store.manifest["status"] == "complete"
    assert sorted(store.cases()["case_id"]) == sorted(ids)
    assert len(stored_parts(results)) == len(ids)  # no case was run and stored twice
    return manifest


#: Two cases of ~4–6 s each on the Python loop (55 µs a step here), so that the run is still
#: writing its second case while a second writer starts (~2 s), whichever case runs first.  The
#: compiled loop's cases of :data:`INTERRUPTIBLE` all end in ~3 s since the loop got faster.
LONG_CASES = """
timeout_s = 120.0
calibration = false

[[group]]
scenarios = ["fourbar"]
methods = { inhouse = ["rk4+direct:loop=python"] }
dts = [5e-5, 4e-5]
"""


def test_a_second_writer_of_a_running_run_is_refused_and_changes_nothing(tmp_path, results):
    path = write_campaign(tmp_path, "long", LONG_CASES)
    run = start_run(path, results)
    try:
        (manifest,) = list_runs(results)
        second = mbh("run", str(path), "--resume", manifest["run_id"], "--quiet", root=results)
        assert second.returncode == 2, second.stderr
        assert f"being written by process {run.pid}, started " in second.stderr
        assert "Traceback" not in second.stderr
        assert list_runs(results)[0]["status"] == "running"  # the first writer's, untouched
    finally:
        run.send_signal(signal.SIGINT)
        run.communicate(timeout=120)
    # The lock went with its process: the run resumes to completion, every case stored once.
    done = mbh("run", str(path), "--resume", manifest["run_id"], "--quiet", root=results)
    assert done.returncode == 0, done.stderr
    ids = {case.case_id for case in load_campaign(path).cases}
    assert sorted(RunStore.open(manifest["run_id"], results).cases()["case_id"]) == sorted(ids)
    assert len(stored_parts(results)) == len(ids)


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP], ids=["SIGTERM", "SIGHUP"])
def test_a_stop_signal_interrupts_like_ctrl_c(tmp_path, results, signum):
    interrupt_and_resume(write_campaign(tmp_path, "interruptible", INTERRUPTIBLE), results, signum)


def test_interrupted_run_resumes_without_duplicates_or_gaps(tmp_path, results):
    path = write_campaign(tmp_path, "interruptible", INTERRUPTIBLE)
    manifest = interrupt_and_resume(path, results, signal.SIGINT)
    store = RunStore.open(manifest["run_id"], results)

    shown = mbh("show", manifest["run_id"], "--json", "--where", "status == 'ok'", root=results)
    assert shown.returncode == 0, shown.stderr
    assert {row["case_id"] for row in json.loads(shown.stdout)} == \
        set(store.cases().query("status == 'ok'")["case_id"])
    bad = mbh("show", manifest["run_id"], "--where", "status ==", root=results)
    assert bad.returncode == 2 and "--where 'status =='" in bad.stderr
    assert "Traceback" not in bad.stderr
    listed = mbh("runs", "--json", root=results)
    assert [row["run_id"] for row in json.loads(listed.stdout)] == [manifest["run_id"]]
    compared = mbh("compare", manifest["run_id"], manifest["run_id"], "--json", root=results)
    assert {row["change"] for row in json.loads(compared.stdout)} == {"unchanged"}


def test_show_rejects_an_unknown_run(results):
    results.mkdir()
    unknown = mbh("show", "no-such-run", root=results)
    assert unknown.returncode == 2 and "no-such-run" in unknown.stderr
    assert "Traceback" not in unknown.stderr


BAD = """
timeout_s = 120.0

[[group]]
scenarios = ["fourbar", "no_such_scene"]
adapters = ["inhouse", "no_such_engine"]
methods = ["rk4+direct", "no_such_method", "rk4+direct:no_such_param=1"]
dts = [-1e-3, 1e-3]
t_end = { fourbar = 0.0105 }
"""


def test_campaign_with_mistakes_is_refused_before_anything_runs(tmp_path, results):
    done = mbh("run", str(write_campaign(tmp_path, "bad", BAD)), root=results)
    assert done.returncode == 2
    assert "Traceback" not in done.stderr
    for mistake in ("no_such_scene", "no_such_engine", "no_such_method", "no_such_param",
                    "-0.001", "does not divide the duration"):
        assert mistake in done.stderr, mistake
    assert str(tmp_path / "bad.toml") in done.stderr
    assert not results.exists() or not any(results.iterdir())  # no run folder was made
