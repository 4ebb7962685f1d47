"""The report's tables, computed from a stored run's case rows (:meth:`mbh._harness.store.runs.RunStore.cases`).

Every table is a :class:`Table` of raw values (str, int, float or None); the HTML and PDF
renderers format the cells with :func:`cell_text` and sort numeric columns by value.

Accuracy levels are on the scenario's main output (``main_output_error``: the largest
|y − y_ref| over the evaluation grid, rad for an angle, m for a length).  A case *reaches* a level
when its status is ``ok`` and its main-output error is at most the level; the fastest case reaching
a level (least ``wall_time_s``) is the Pareto-optimal choice at that level.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

from mbh._harness.common.status import CaseStatus

#: Accuracy levels of the summary, rad or m on the main output (every decade 1e-2 … 1e-10).
ACCURACY_LEVELS = tuple(10.0 ** -k for k in range(2, 11))


@dataclass(frozen=True)
class Table:
    """A table of the report.

    Attributes
    ----------
    key : str
        Identifier, unique within a report (the HTML id).
    caption : str
        What the table shows (units in the column names).
    columns : tuple of str
    rows : tuple of tuple
        One tuple of raw values per row, aligned with ``columns``.
    note : str
        What to read from it (shown under the table); "" for none.
    """

    key: str
    caption: str
    columns: tuple[str, ...]
    rows: tuple[tuple, ...]
    note: str = ""


def is_missing(value) -> bool:
    """True for None, pandas' NA and a float NaN."""
    return value is None or value is pd.NA or (isinstance(value, float) and math.isnan(value))


def cell_text(value) -> str:
    """A cell as text: floats in 3 significant digits, missing values as an em dash."""
    if is_missing(value):
        return "—"
    if isinstance(value, (bool, np.bool_)):
        return "yes" if value else "no"
    if isinstance(value, (float, np.floating)):
        return f"{value:.3g}"
    return str(value)


def sort_key(value) -> float | None:
    """The numeric sort value of a cell (None for text and missing values)."""
    if is_missing(value) or isinstance(value, (str, bool, np.bool_)):
        return None
    if isinstance(value, (int, float, np.integer, np.floating)):
        return float(value)
    return None


def _plain(value):
    """A pandas/numpy scalar as a plain Python value (NA → None)."""
    if is_missing(value):
        return None
    return value.item() if isinstance(value, np.generic) else value


def _calibrated(seconds, calibration_s: float | None):
    if calibration_s is None or is_missing(seconds):
        return None
    return float(seconds) / calibration_s


def reaching(cases: pd.DataFrame, level: float) -> pd.DataFrame:
    """Cases with status ``ok`` and main-output error ≤ ``level``, fastest first."""
    error = cases["main_output_error"].astype(float)
    hits = cases[(cases["status"] == CaseStatus.OK) & (error <= level)]
    return hits.sort_values(["wall_time_s", "case_id"], kind="stable")


def fastest_table(cases: pd.DataFrame, scenario: str, calibration_s: float | None,
                  levels=ACCURACY_LEVELS) -> Table:
    """The fastest ``ok`` engine/method reaching each accuracy level on ``scenario``."""
    mine = cases[cases["scenario"] == scenario]
    output = _plain(mine["main_output"].dropna().iloc[0]) if mine["main_output"].notna().any() else "?"
    rows = []
    for level in levels:
        hits = reaching(mine, level)
        if hits.empty:
            rows.append((level, "none reaches it", None, None, None, None, None, 0))
            continue
        best = hits.iloc[0]
        rows.append((level, _plain(best["adapter"]), _plain(best["method"]), _plain(best["dt"]),
                     _plain(best["main_output_error"]), _plain(best["wall_time_s"]),
                     _calibrated(best["wall_time_s"], calibration_s), len(hits)))
    return Table(
        key=f"fastest-{slug(scenario)}",
        caption=f"{scenario}: fastest ok case reaching each accuracy level on {output}",
        columns=("level", "adapter", "method", "dt (s)", "error", "wall time (s)",
                 "wall time / calibration", "cases reaching"),
        rows=tuple(rows),
        note="The Pareto front read at each level: no case that reaches the level is faster.")


#: The adapter whose front :func:`front_ratio_table` sets against the engines'.
INHOUSE = "inhouse"


def front_ratio_table(cases: pd.DataFrame, scenario: str, levels=ACCURACY_LEVELS) -> Table:
    """The in-house Pareto front against the engines': per accuracy level on ``scenario``, the
    fastest ``ok`` in-house case reaching it, the fastest ``ok`` engine case reaching it, and the
    ratio of their wall times (in-house / engine; below 1: the in-house formulation is faster)."""
    mine = cases[cases["scenario"] == scenario]
    own, engines = mine[mine["adapter"] == INHOUSE], mine[mine["adapter"] != INHOUSE]
    rows = []
    for level in levels:
        ours, theirs = reaching(own, level), reaching(engines, level)
        ours = None if ours.empty else ours.iloc[0]
        theirs = None if theirs.empty else theirs.iloc[0]
        ratio = (float(ours["wall_time_s"]) / float(theirs["wall_time_s"])
                 if ours is not None and theirs is not None else None)
        rows.append((level, *_front_pick(ours), *_front_pick(theirs, with_adapter=True), ratio))
    return Table(
        key=f"front-{slug(scenario)}",
        caption=f"{scenario}: in-house front against the fastest engine at each accuracy level",
        columns=("level", "in-house method", "dt (s)", "wall time (s)", "engine",
                 "engine method", "engine dt (s)", "engine wall time (s)",
                 "in-house / engine time"),
        rows=tuple(rows),
        note="Each side's fastest ok case whose main-output error is within the level; an empty "
             "side reaches no case at that level.")


def _front_pick(case, with_adapter: bool = False) -> tuple:
    if case is None:
        return (None,) * (4 if with_adapter else 3)
    picked = (_plain(case["method"]), _plain(case["dt"]), _plain(case["wall_time_s"]))
    return ((_plain(case["adapter"]),) if with_adapter else ()) + picked


def pareto_table(cases: pd.DataFrame, levels=ACCURACY_LEVELS) -> Table:
    """Per scenario (rows) and accuracy level (columns): ``"adapter method dt=…"`` of the fastest
    ``ok`` case reaching the level (None when no case does)."""
    rows = []
    for scenario in sorted(cases["scenario"].dropna().unique()):
        mine = cases[cases["scenario"] == scenario]
        picks = []
        for level in levels:
            hits = reaching(mine, level)
            best = None if hits.empty else hits.iloc[0]
            picks.append(None if best is None else
                         f"{best['adapter']} {best['method']} dt={best['dt']:g}")
        rows.append((scenario, *picks))
    return Table(key="pareto", caption="Fastest ok engine/method reaching each accuracy level "
                 "on the main output (rad or m)",
                 columns=("scenario", *(f"≤ {level:g}" for level in levels)), rows=tuple(rows),
                 note="A dash: no case of the run reaches the level. Details per scenario below.")


def status_counts_table(cases: pd.DataFrame) -> Table:
    """Case counts by status per scenario and adapter."""
    statuses = [s for s in CaseStatus if (cases["status"] == s).any()]
    statuses += sorted(set(cases["status"].dropna()) - set(statuses))
    rows = []
    for (scenario, adapter), group in cases.groupby(["scenario", "adapter"], sort=True):
        counts = group["status"].value_counts()
        rows.append((scenario, adapter, *(int(counts.get(s, 0)) for s in statuses), len(group)))
    return Table(key="status-counts", caption="Cases by status per scenario and engine",
                 columns=("scenario", "adapter", *statuses, "total"), rows=tuple(rows))


def failures_table(cases: pd.DataFrame) -> Table:
    """Every case whose status is not ``ok``, with its reason and failure time."""
    failed = cases[cases["status"] != CaseStatus.OK]
    rows = tuple((_plain(r["scenario"]), _plain(r["adapter"]), _plain(r["method"]),
                  _plain(r["dt"]), _plain(r["status"]), _plain(r["failure_time"]),
                  _plain(r["reason"])) for _, r in failed.iterrows())
    return Table(key="failures", caption="Cases that did not end ok",
                 columns=("scenario", "adapter", "method", "dt (s)", "status",
                          "failure time (s)", "reason"), rows=rows)


def changes_table(changes: pd.DataFrame) -> Table:
    """The cases that changed class between the previous run and this one.

    ``changes`` is :func:`mbh._harness.store.compare.compare_runs` (previous run as ``a``, this run as ``b``).
    """
    changed = changes[changes["change"] != "unchanged"]
    counts = changes["change"].value_counts()
    rows = tuple((_plain(r["change"]), _plain(r["scenario"]), _plain(r["adapter"]),
                  _plain(r["method"]), _plain(r["dt"]), _plain(r["status_a"]),
                  _plain(r["status_b"]), _plain(r["error_ratio"]), _plain(r["time_ratio"]))
                 for _, r in changed.iterrows())
    summary = ", ".join(f"{change} {int(count)}" for change, count in counts.items())
    return Table(key="changes", caption="Changes against the previous run",
                 columns=("change", "scenario", "adapter", "method", "dt (s)", "status before",
                          "status now", "error ratio (now / before)",
                          "calibrated time ratio (now / before)"),
                 rows=rows,
                 note=f"{len(changes)} cases in both runs: {summary or 'none'}. Time ratios are of "
                      f"wall times divided by each run's calibration time.")


def model_size_table(cases: pd.DataFrame, accuracy: float) -> Table:
    """Model size per scenario, engine and model next to its cost: one row per distinct size an
    engine carried for the scene (the in-house formulation's absolute and joint-coordinate
    models side by side), a row with no size for cases whose engine could not build.

    Cost is the median wall time per step over the row's ``ok`` cases, and the least wall time
    of a case reaching ``accuracy`` on the main output.
    """
    size_columns = ["n_coordinates", "n_constraint_equations", "n_redundant_equations"]
    rows = []
    for key, group in cases.groupby(["scenario", "adapter", *size_columns], sort=True,
                                    dropna=False):
        scenario, adapter, *sizes = key
        ok = group[group["status"] == CaseStatus.OK]
        per_step = ok["wall_time_per_step_s"].astype(float).median() if len(ok) else None
        hits = reaching(group, accuracy)
        notes = group["model_notes"].dropna()
        rows.append((
            scenario, adapter, *(None if pd.isna(size) else int(size) for size in sizes),
            _plain(per_step), None if hits.empty else _plain(hits.iloc[0]["wall_time_s"]),
            _plain(notes.iloc[0]) if len(notes) else ""))
    return Table(key="model-size", caption="Model size per engine next to its cost",
                 columns=("scenario", "adapter", "coordinates", "constraint equations",
                          "redundant equations", "median wall time per step (s)",
                          f"fastest to {accuracy:g} (s)", "what the engine carried"),
                 rows=tuple(rows),
                 note="Coordinates and equations of the model each engine builds for the "
                      "scene, one row per model (the in-house absolute and joint-coordinate "
                      "models each have their own), with the cost of that model's cases.")


def cases_table(cases: pd.DataFrame, calibration_s: float | None) -> Table:
    """Every case of the run, one row each."""
    rows = tuple((_plain(r["scenario"]), _plain(r["adapter"]), _plain(r["method"]),
                  _plain(r["dt"]), _plain(r["status"]), _plain(r["accurate"]),
                  _plain(r["main_output_error"]), _plain(r["max_constraint_violation"]),
                  _plain(r["max_energy_error_rel"]), _plain(r["wall_time_s"]),
                  _calibrated(r["wall_time_s"], calibration_s))
                 for _, r in cases.iterrows())
    return Table(key="cases", caption="All cases",
                 columns=("scenario", "adapter", "method", "dt (s)", "status", "accurate",
                          "main output error", "max constraint violation",
                          "max energy error (rel.)", "wall time (s)", "wall time / calibration"),
                 rows=rows)


def slug(text: str) -> str:
    """``text`` as a unique HTML-id-safe name: its letters and digits, then a short hash."""
    readable = "".join(c if c.isascii() and c.isalnum() else "-" for c in text).strip("-")
    return f"{readable[:40] or 'x'}-{hashlib.sha256(text.encode()).hexdigest()[:8]}"
