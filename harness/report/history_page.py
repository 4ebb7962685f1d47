"""The history page of a campaign: one self-contained HTML file (no network, the run report's
conventions: jinja2 template, inline SVG figures, the report's CSS and sortable tables).

It shows the runs (commit, calibration, engine versions, a link to each run's report where one
was built), the changes :func:`mbh._harness.report.history.find_changes` found (open regressions
first, each linking to the report of its first run), and one trend figure
(:func:`mbh._harness.report.history_figures.trend_figure`) per scenario × engine × method family,
with filters by scenario, engine and "changed only".  A campaign with a single finished run has
no history yet: the page says so and draws no figure.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from mbh._harness.common.locations import checkout
from mbh._harness.report.build import _asset, _environment_for_template, build_time, reports_root
from mbh._harness.report.history import (QUANTITIES, STATUS, History, find_changes, load_history,
                                    version_changes)
from mbh._harness.report.history_figures import method_family, trend_figure
from mbh._harness.report.style import Figure
from mbh._harness.store.location import results_root

__all__ = ["HistoryPage", "TrendView", "collect_history", "render_history", "build_history",
           "report_link", "HISTORY_FILE"]

#: File name of the page in its folder.
HISTORY_FILE = "history.html"


@dataclass(frozen=True)
class TrendView:
    """One trend figure and what the page's filters read."""

    scenario: str
    adapter: str
    family: str
    changed: bool
    figure: Figure


@dataclass(frozen=True)
class HistoryPage:
    """Everything the history page shows."""

    campaign: str
    built_at: str
    runs: list[dict]
    changes: list[dict]
    trends: list[TrendView]
    command: str

    @property
    def single_run(self) -> bool:
        """Whether the campaign has one finished run only (no history to show yet)."""
        return len(self.runs) < 2

    @property
    def scenarios(self) -> list[str]:
        return sorted({view.scenario for view in self.trends})

    @property
    def adapters(self) -> list[str]:
        return sorted({view.adapter for view in self.trends})


def _report_places(run_id: str, root: Path) -> list[Path]:
    """Where a report of run ``run_id`` under ``root`` is written: in the run folder
    (``mbh nightly``), in the results root's reports folder (``mbh report``) and, in a checkout,
    in its ``reports`` folder (``make report``)."""
    places = [root / run_id / "report" / "report.html", reports_root(root) / run_id / "report.html"]
    repository = checkout()
    if repository is not None:
        places.append(repository / "reports" / run_id / "report.html")
    return places


def report_link(run_id: str, root: Path, page_folder: Path) -> str | None:
    """The path of run ``run_id``'s HTML report relative to ``page_folder``, or None when no
    report of it was built."""
    for path in _report_places(run_id, root):
        if path.is_file():
            return Path(os.path.relpath(path, page_folder)).as_posix()
    return None


def _engine_versions(history: History) -> dict[int, str]:
    """Run index → ``"adapter version, …"`` (the versions most of each engine's rows carry)."""
    versions = (history.cases.dropna(subset=["adapter_version"])
                .groupby(["run", "adapter"])["adapter_version"]
                .agg(lambda v: v.mode().iloc[0]))
    text: dict[int, list[str]] = {}
    for (run, adapter), version in versions.items():
        text.setdefault(int(run), []).append(f"{adapter} {version}")
    return {run: ", ".join(parts) for run, parts in text.items()}


def _change_rows(changes: pd.DataFrame, links: dict[str, str | None]) -> list[dict]:
    """The changes as template rows, open regressions first."""
    ordered = changes.assign(_closed=~(changes["open"] & (changes["kind"] == "regression")))
    ordered = ordered.sort_values("_closed", kind="stable")
    rows = []
    for change in ordered.to_dict("records"):
        what = "status" if change["quantity"] == STATUS else QUANTITIES[change["quantity"]][0]
        rows.append({**change, "what": what, "link": links.get(change["run_id"])})
    return rows


def _trends(history: History, changes: pd.DataFrame) -> list[TrendView]:
    """One trend figure per scenario × engine × method family of ``history``."""
    upgrades = version_changes(history)
    cases = history.cases.assign(family=history.cases["method"].map(method_family))
    changes = changes.assign(family=changes["method"].map(method_family))
    trends = []
    for (scenario, adapter, family), group in cases.groupby(["scenario", "adapter", "family"],
                                                            sort=True):
        mine = changes[(changes["scenario"] == scenario) & (changes["adapter"] == adapter)
                       & (changes["family"] == family)]
        title = f"{scenario} · {adapter} · {family}"
        trends.append(TrendView(scenario, adapter, family, not mine.empty, trend_figure(
            title, history.runs, group, mine, upgrades[upgrades["adapter"] == adapter])))
    return trends


def collect_history(campaign: str | None = None, root: Path | None = None,
                    page_folder: Path | None = None, built_at: str | None = None,
                    history: History | None = None,
                    changes: pd.DataFrame | None = None) -> HistoryPage:
    """The page's content for ``campaign`` under ``root`` (links relative to ``page_folder``).

    ``history`` and ``changes`` (from :func:`load_history` and :func:`find_changes`) are read
    from the store when not given.
    """
    history = history if history is not None else load_history(campaign, root)
    changes = changes if changes is not None else find_changes(history)
    store_root = Path(root) if root is not None else results_root()
    folder = Path(page_folder) if page_folder is not None else Path.cwd()
    links = {run: report_link(run, store_root, folder) for run in history.runs["run_id"]}
    versions = _engine_versions(history)
    runs = [{**run, "index": index, "versions": versions.get(index, ""),
             "link": links[run["run_id"]]}
            for index, run in enumerate(history.runs.drop(columns="packages").to_dict("records"))]
    trends = _trends(history, changes) if len(runs) > 1 else []  # one run: no trend yet
    root_option = f" --root {root}" if root is not None else ""
    return HistoryPage(campaign=history.campaign, built_at=built_at or build_time(), runs=runs,
                       changes=_change_rows(changes, links), trends=trends,
                       command=f"mbh history --campaign {history.campaign}{root_option}")


def render_history(page: HistoryPage) -> str:
    """The page as one self-contained HTML document (no external fetches)."""
    template = _environment_for_template().get_template("history.html.j2")
    return template.render(page=page, css=_asset("report.css"), js=_asset("report.js"),
                           history_js=_asset("history.js"))


def build_history(campaign: str | None = None, root: Path | None = None,
                  out: Path | None = None, built_at: str | None = None,
                  history: History | None = None,
                  changes: pd.DataFrame | None = None) -> Path:
    """Write the history page of ``campaign`` into ``out`` (default
    ``<results root>/reports/history-<campaign>/``, :func:`reports_root`) and return its path.

    Raises
    ------
    mbh._harness.report.history.HistoryError
        When the root holds no finished run of the campaign.
    """
    history = history if history is not None else load_history(campaign, root)
    folder = Path(out) if out is not None else reports_root(root) / f"history-{history.campaign}"
    folder.mkdir(parents=True, exist_ok=True)
    page = collect_history(history.campaign, root, folder, built_at, history, changes)
    path = folder / HISTORY_FILE
    path.write_text(render_history(page), encoding="utf-8")
    return path
