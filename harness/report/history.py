"""A campaign's history: every stored run of it, per case, and the steps in each case's series.

:func:`load_history` reads the finished runs of one campaign (status ``complete`` or
``interrupted``, oldest start first) from the store: per run its commit, dirty flag, calibration
time and engine versions; per run and case its status, errors and calibrated wall time.
:func:`find_changes` then lists every change of every case, in the order they count:

1. **status**: the case turns from ``ok`` to not ``ok`` (a regression) or back (an improvement),
   counted at the first run with the new status (a status is observed, not estimated: confidence
   1);
2. **accuracy**: steps in the main-output error, the constraint violation and the energy error
   (:data:`mbh._harness.report.changepoints.ERROR`, over the runs where the case ended ``ok``);
3. **time**: steps in the calibrated wall time (wall time / the run's calibration time,
   :data:`mbh._harness.report.changepoints.TIME`), only beyond the series' measured noise.

A change is *open* when the case's latest level is still beyond the rule's least factor from the
level before the change (a regression not undone since).  Engine versions come from the case rows
(``adapter_version``): a change at a run where the case's engine version changed names the
upgrade.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from mbh._harness.common.status import FINISHED_RUN_STATUSES, CaseStatus
from mbh._harness.common.errors import MbhError
from mbh._harness.report.changepoints import ERROR, TIME, SeriesRule, detect_steps
from mbh._harness.store.manifest import list_runs
from mbh._harness.store.runs import RunStore

__all__ = ["QUANTITIES", "STATUS", "History", "HistoryError", "load_history", "find_changes",
           "version_changes", "open_regressions"]

#: The measured quantities of a history, in the order their changes count: column → (what it
#: is, unit, rule).
QUANTITIES: dict[str, tuple[str, str, SeriesRule]] = {
    "main_output_error": ("main-output error", "rad or m", ERROR),
    "max_constraint_violation": ("constraint violation", "m", ERROR),
    "max_energy_error_rel": ("energy error", "of the energy scale", ERROR),
    "calibrated_time": ("calibrated wall time", "wall time / calibration time", TIME),
}
#: Name of the status "quantity" in :func:`find_changes`.
STATUS = "status"
#: Columns of the case rows a history keeps (besides the calibrated time it adds).
_CASE_COLUMNS = ["case_id", "scenario", "adapter", "method", "dt", "status", "adapter_version",
                 "main_output_error", "max_constraint_violation", "max_energy_error_rel",
                 "wall_time_s"]
#: Columns of :func:`find_changes`.
CHANGE_COLUMNS = ["case_id", "scenario", "adapter", "method", "dt", "quantity", "kind", "run",
                  "run_id", "commit", "version_change", "before", "after", "factor",
                  "confidence", "open"]


class HistoryError(MbhError, ValueError):
    """A history that cannot be built as asked (no run of the campaign, unreadable runs)."""


@dataclass(frozen=True)
class History:
    """The stored runs of one campaign.

    Attributes
    ----------
    campaign : str
    root : Path or None
        Results root read (None: the default).
    runs : DataFrame
        One row per run, oldest first, index 0 … n−1: ``run_id``, ``started``, ``status``,
        ``commit`` (12 characters, ``+dirty`` appended for a dirty tree), ``calibration_s`` (s;
        NaN without a figure, or when its workload differs from the newest run's),
        ``packages`` (dict: package → version).
    cases : DataFrame
        One row per run and case: ``run`` (index into ``runs``) and :data:`_CASE_COLUMNS` plus
        ``calibrated_time`` (wall time / calibration time; NaN without a calibration).
    """

    campaign: str
    root: Path | None
    runs: pd.DataFrame
    cases: pd.DataFrame


def _commit(manifest: dict) -> str:
    git = manifest.get("git") or {}
    commit = str(git.get("commit") or "unknown")[:12]
    return commit + ("+dirty" if git.get("dirty") else "")


def load_history(campaign: str | None = None, root: Path | None = None) -> History:
    """Every finished stored run of ``campaign`` (default: the campaign of the latest finished
    run under ``root``).

    Raises
    ------
    HistoryError
        When the root holds no finished run (of that campaign), naming the root and the
        campaigns it holds.
    """
    manifests = [m for m in list_runs(root) if m["status"] in FINISHED_RUN_STATUSES]
    if campaign is None and manifests:
        campaign = manifests[-1]["campaign"]
    mine = [m for m in manifests if m["campaign"] == campaign]
    if not mine:
        held = sorted({m["campaign"] for m in manifests})
        raise HistoryError(f"{root or 'the results root'}: no finished run of campaign "
                           f"{campaign!r}" + (f" (campaigns stored: {', '.join(held)})" if held
                                              else " (no finished run at all)"))
    runs, frames = [], []
    stores = [RunStore.open(manifest["run_id"], root) for manifest in mine]
    for index, (manifest, store) in enumerate(zip(mine, stores)):
        # Calibrated times compare only between runs whose figure the same workload measured:
        # the newest run's (an older numpy or scipy, or an older calibration, gives NaN).
        calibration = (store.calibration_s
                       if store.calibration_workload == stores[-1].calibration_workload else None)
        runs.append({"run_id": manifest["run_id"], "started": manifest["started"],
                     "status": manifest["status"], "commit": _commit(manifest),
                     "calibration_s": float(calibration) if calibration else np.nan,
                     "packages": dict(manifest.get("packages") or {})})
        rows = store.cases().reindex(columns=_CASE_COLUMNS)
        rows.insert(0, "run", index)
        wall = rows["wall_time_s"].to_numpy(float, na_value=np.nan)
        rows["calibrated_time"] = wall / calibration if calibration else np.nan
        frames.append(rows)
    cases = pd.concat(frames, ignore_index=True)
    for column in QUANTITIES:
        cases[column] = cases[column].to_numpy(float, na_value=np.nan)
    return History(campaign, root, pd.DataFrame(runs), cases)


def version_changes(history: History) -> pd.DataFrame:
    """The runs at which an engine's version changed: ``run``, ``adapter``, ``before``,
    ``after`` (the version most of the adapter's rows carry in each run)."""
    rows = []
    versions = (history.cases.dropna(subset=["adapter_version"])
                .groupby(["adapter", "run"])["adapter_version"]
                .agg(lambda v: v.mode().iloc[0]))
    for adapter, series in versions.groupby(level="adapter"):
        series = series.droplevel("adapter")
        for (_, before), (run, after) in zip(series.items(), list(series.items())[1:]):
            if before != after:
                rows.append({"run": int(run), "adapter": adapter, "before": before,
                             "after": after})
    return pd.DataFrame(rows, columns=["run", "adapter", "before", "after"])


def _version_note(case: pd.DataFrame, run: int) -> str:
    """``"ENGINE A → B"`` when the case's engine version changed at ``run``, else ""."""
    earlier = case[case["run"] < run]["adapter_version"].dropna()
    now = case[case["run"] == run]["adapter_version"].dropna()
    if earlier.empty or now.empty or earlier.iloc[-1] == now.iloc[0]:
        return ""
    return f"{case['adapter'].iloc[0]} {earlier.iloc[-1]} → {now.iloc[0]}"


def _status_changes(case: pd.DataFrame) -> list[dict]:
    """Every ok ↔ not-ok flip of one case's status (runs where it is stored)."""
    statuses = case["status"].tolist()
    runs = case["run"].tolist()
    ok = np.array([s == CaseStatus.OK for s in statuses])
    changes = []
    for position in np.flatnonzero(ok[1:] != ok[:-1]) + 1:
        regression = not ok[position]
        changes.append({"quantity": STATUS, "kind": "regression" if regression else
                        "improvement", "run": runs[position], "before": statuses[position - 1],
                        "after": statuses[position], "factor": np.nan, "confidence": 1.0,
                        "open": bool(regression and not ok[-1])})
    return changes


def _quantity_changes(case: pd.DataFrame, column: str, rule: SeriesRule) -> list[dict]:
    """The steps of one quantity of one case over the runs where it ended ``ok``."""
    ok = case[(case["status"] == CaseStatus.OK) & np.isfinite(case[column]) & (case[column] >= 0)]
    values, runs = ok[column].to_numpy(float), ok["run"].to_numpy(int)
    steps = detect_steps(values, rule)
    latest = steps[-1].after if steps else None
    changes = []
    for step in steps:
        worse = step.factor > 1.0
        net = latest / step.before if worse else step.before / latest
        changes.append({"quantity": column, "kind": "regression" if worse else "improvement",
                        "run": int(runs[step.index]), "before": step.before,
                        "after": step.after, "factor": step.factor,
                        "confidence": step.confidence,
                        "open": bool(worse and net >= rule.min_factor)})
    return changes


def find_changes(history: History) -> pd.DataFrame:
    """Every change of every case (see the module docstring), one row each.

    Returns
    -------
    DataFrame
        :data:`CHANGE_COLUMNS`: the case (``case_id``, ``scenario``, ``adapter``, ``method``,
        ``dt``), ``quantity`` (:data:`STATUS` or a key of :data:`QUANTITIES`), ``kind``
        (``regression`` or ``improvement``), ``run`` (index of the first run at the new level)
        with its ``run_id`` and ``commit``, ``version_change`` (the engine upgrade at that run,
        or ""), ``before`` and ``after`` (levels, or statuses), ``factor`` (after / before; NaN
        for a status), ``confidence`` and ``open``.  Sorted status first, then accuracy, then
        time; within each by run and case.
    """
    rows = []
    for case_id, case in history.cases.sort_values("run").groupby("case_id", sort=True):
        found = _status_changes(case)
        for column, (_, _, rule) in QUANTITIES.items():
            found += _quantity_changes(case, column, rule)
        first = case.iloc[0]
        for change in found:
            run = history.runs.iloc[change["run"]]
            rows.append({"case_id": case_id, "scenario": first["scenario"],
                         "adapter": first["adapter"], "method": first["method"],
                         "dt": float(first["dt"]), **change, "run_id": run["run_id"],
                         "commit": run["commit"],
                         "version_change": _version_note(case, change["run"])})
    changes = pd.DataFrame(rows, columns=CHANGE_COLUMNS)
    order = {name: rank for rank, name in enumerate([STATUS, *QUANTITIES])}
    changes["_order"] = changes["quantity"].map(order)
    return (changes.sort_values(["_order", "run", "case_id"], kind="stable")
            .drop(columns="_order").reset_index(drop=True))


def open_regressions(changes: pd.DataFrame) -> pd.DataFrame:
    """The rows of :func:`find_changes` that are regressions still open at the latest run."""
    return changes[(changes["kind"] == "regression") & changes["open"]]
