"""The trend figure of one scenario × engine × method family over a campaign's runs.

Three panels share the run axis.  The first holds the errors (main output, constraint violation,
energy: :data:`mbh._harness.report.history.QUANTITIES`), the second the calibrated wall time, each
value divided by the case's own median over the runs where it ended ``ok`` (so cases of every step
size share one axis and a step shows as a move away from 1); the third the number of cases that
ended ``ok`` per run.  A case with a change in a quantity is drawn as a line of its own with each
step marked (▲ regression, ▼ improvement, a dotted line at its first run); the other cases are
one grey band (their per-run range).  Engine version changes are dashed lines, named in the top
panel; the x axis carries each run's commit and the engine's version.
"""

from __future__ import annotations

import textwrap

import numpy as np
import pandas as pd
from matplotlib.ticker import NullLocator

from mbh._harness.common.status import CaseStatus
from mbh._harness.report.history import QUANTITIES, STATUS
from mbh._harness.report.style import Figure, new_figure, plain, render, series_style

#: Colours of a regression and an improvement (Okabe–Ito vermillion and bluish green).
KIND_COLOURS = {"regression": "#D55E00", "improvement": "#009E73"}
KIND_MARKERS = {"regression": "^", "improvement": "v"}
#: Most x tick labels on one axis (every k-th run is labelled beyond that).
MAX_LABELS = 16
#: Most characters on a line of a legend entry (a longer one wraps): the legend sits beside the
#: panels, and one long method string squeezed them to nothing.
LEGEND_WIDTH = 40
_BAND = "#BBBBBB"
#: The quantities of the first panel and of the second.
TIME_COLUMN = "calibrated_time"
ERRORS = [column for column in QUANTITIES if column != TIME_COLUMN]


#: The methods every adapter has (docs/methods.md), drawn in one figure per engine.
PRESETS = ("default", "best")


def method_family(method: str) -> str:
    """The family of a method string: ``"default & best"`` for the presets every adapter has,
    else the integrator before ``+`` or ``:`` (``rk4+direct`` → ``rk4``, ``ida:rtol=1e-6`` →
    ``ida``)."""
    if method in PRESETS:
        return " & ".join(PRESETS)
    return method.split("+", 1)[0].split(":", 1)[0]


def _case_label(row) -> str:
    return f"{row['method']} dt={row['dt']:g}"


def _legend_entry(text: str) -> str:
    """``text`` as a legend entry: wrapped to :data:`LEGEND_WIDTH`, escaped for matplotlib."""
    return plain("\n".join(textwrap.wrap(text, LEGEND_WIDTH, break_long_words=True)))


def _relative(case: pd.DataFrame, column: str, runs: int) -> np.ndarray:
    """The case's ``column`` over its median of ``ok`` runs, shape (runs,), NaN where not ok."""
    values = np.full(runs, np.nan)
    ok = case[(case["status"] == CaseStatus.OK) & (case[column] > 0)]
    if len(ok):
        values[ok["run"].to_numpy(int)] = ok[column].to_numpy(float) / np.median(ok[column])
    return values


def _band(axes, stack: list[np.ndarray], x: np.ndarray, what: str) -> None:
    """The per-run range of the rows of ``stack`` as a grey band."""
    if not stack:
        return
    values = np.vstack(stack)
    drawn = np.isfinite(values).any(axis=0)
    low = np.min(np.where(np.isfinite(values), values, np.inf), axis=0)
    high = np.max(np.where(np.isfinite(values), values, -np.inf), axis=0)
    axes.fill_between(x, np.where(drawn, low, np.nan), np.where(drawn, high, np.nan),
                      color=_BAND, alpha=0.6, edgecolor=_BAND, linewidth=1.0,
                      label=plain(what))


def _draw_quantities(axes, cases: pd.DataFrame, changes: pd.DataFrame, columns: list[str],
                     runs: int, ylabel: str) -> None:
    """One panel of ``columns``: changed (case, quantity) series as lines with their steps
    marked, the others as one band."""
    x = np.arange(runs)
    changed = set(zip(changes["case_id"], changes["quantity"]))
    unchanged, index = [], 0
    for case_id, case in cases.groupby("case_id", sort=True):
        for column in columns:
            values = _relative(case, column, runs)
            if (case_id, column) not in changed:
                unchanged.append(values)
                continue
            name = QUANTITIES[column][0]
            axes.plot(x, values, markersize=2.5,
                      label=_legend_entry(f"{_case_label(case.iloc[0])}: {name}"),
                      **series_style(index))
            index += 1
            mine = changes[(changes["case_id"] == case_id) & (changes["quantity"] == column)]
            for change in mine.itertuples():
                colour = KIND_COLOURS[change.kind]
                axes.axvline(change.run, color=colour, linestyle=":", linewidth=0.9)
                axes.plot([change.run], [values[change.run]], linestyle="none", markersize=8,
                          marker=KIND_MARKERS[change.kind], color=colour)
    _band(axes, unchanged, x, f"{len(unchanged)} unchanged series: range")
    axes.set_yscale("log")
    axes.yaxis.set_minor_locator(NullLocator())
    axes.set_ylabel(plain(ylabel))
    axes.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), frameon=False)


def _draw_status(axes, cases: pd.DataFrame, changes: pd.DataFrame, runs: int) -> None:
    """The last panel: cases ``ok`` per run, status changes marked."""
    ok = cases.assign(ok=cases["status"] == CaseStatus.OK)
    counts = ok.groupby("run")["ok"].agg(["sum", "size"])
    counts = counts.reindex(range(runs))
    axes.step(np.arange(runs), counts["sum"], where="mid", color="#0072B2", label="cases ok")
    axes.step(np.arange(runs), counts["size"], where="mid", color=_BAND, label="cases stored")
    for change in changes[changes["quantity"] == STATUS].itertuples():
        axes.plot([change.run], [counts["sum"].iloc[change.run]], linestyle="none",
                  marker=KIND_MARKERS[change.kind], markersize=8,
                  color=KIND_COLOURS[change.kind])
    axes.set_ylabel("cases")
    axes.set_ylim(bottom=0)
    axes.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), frameon=False)


def _tick_labels(runs: pd.DataFrame, versions: dict[int, str]) -> tuple[list, list]:
    """(positions, labels): each labelled run's commit and the engine version it ran."""
    every = max(1, int(np.ceil(len(runs) / MAX_LABELS)))
    positions = list(range(0, len(runs), every))
    return positions, [f"{runs['commit'].iloc[i][:7]}\n{versions.get(i, '?')}" for i in positions]


def trend_figure(title: str, runs: pd.DataFrame, cases: pd.DataFrame, changes: pd.DataFrame,
                 upgrades: pd.DataFrame) -> Figure:
    """The trend figure of one group of cases (see the module docstring).

    Parameters
    ----------
    title : str
        ``scenario · adapter · family``.
    runs : DataFrame
        :attr:`mbh._harness.report.history.History.runs`.
    cases : DataFrame
        The group's rows of :attr:`History.cases` (one engine).
    changes : DataFrame
        The group's rows of :func:`mbh._harness.report.history.find_changes`.
    upgrades : DataFrame
        The engine's rows of :func:`mbh._harness.report.history.version_changes`.
    """
    n = len(runs)
    figure = new_figure(8.0, 6.0)
    panels = figure.subplots(3, 1, sharex=True, height_ratios=(2, 2, 1))
    _draw_quantities(panels[0], cases, changes, ERRORS, n, "errors / case median")
    _draw_quantities(panels[1], cases, changes, [TIME_COLUMN], n,
                     "calibrated time\n/ case median")
    _draw_status(panels[2], cases, changes, n)
    for upgrade in upgrades.itertuples():
        for axes in panels:
            axes.axvline(upgrade.run - 0.5, color="#555555", linestyle="--", linewidth=0.9)
        panels[0].annotate(plain(f"{upgrade.adapter} {upgrade.before} → {upgrade.after}"),
                           (upgrade.run - 0.5, 1.0), xycoords=("data", "axes fraction"),
                           fontsize=7, rotation=90, va="top", ha="right")
    versions = cases.dropna(subset=["adapter_version"]).groupby("run")["adapter_version"].first()
    positions, labels = _tick_labels(runs, versions.to_dict())
    panels[-1].set_xticks(positions, [plain(label) for label in labels], fontsize=6.5,
                          rotation=60, ha="right")
    panels[-1].set_xlim(-0.5, n - 0.5)
    panels[0].set_title(plain(title))
    regressions = int((changes["kind"] == "regression").sum())
    improvements = len(changes) - regressions
    caption = (f"{n} runs, {cases['case_id'].nunique()} cases; {regressions} regression(s) ▲, "
               f"{improvements} improvement(s) ▼; dashed: engine version changes.")
    alt = (f"{title}: each measured quantity over {n} runs relative to each case's median; "
           + ("; ".join(f"{c.kind} of {QUANTITIES.get(c.quantity, (c.quantity,))[0]} in "
                        f"{c.method} dt={c.dt:g} at run {c.run} ({c.commit})"
                        for c in changes.itertuples()) or "no change found") + ".")
    return render(figure, title, caption, alt)
