"""``mbh nightly``: run a campaign, compare it with the previous run of the same campaign, build
its reports and gate on regressions.

Steps of :func:`nightly`:

1. the previous run: the latest ``complete`` run of the same campaign (by name) under the results
   root, looked up before this run starts;
2. the campaign runs into the store (:func:`harness.run.campaign.run_campaign`, calibration case
   included);
3. the two runs are compared case by case (:func:`harness.store.compare.compare_runs`: errors as ratios,
   wall times as ratios of calibrated times, i.e. each divided by its own run's calibration case);
4. the reports are built into ``<run folder>/report/`` when :mod:`harness.report.build` is
   installed (otherwise the step is skipped with a note);
5. a short summary, printed and written as Markdown (``<run folder>/nightly_summary.md`` unless
   given, and appended to ``$GITHUB_STEP_SUMMARY`` when that is set).

A regression is a case present in both runs that is :data:`REGRESSIONS`: newly failing (``ok``
before, not ``ok`` now: failed, diverged, crashed, timeout, unsupported), less accurate (main
output error more than ``error_factor`` times the previous one) or slower (calibrated time more
than ``time_factor`` times the previous one).  The thresholds are command-line options: the
campaign file format (:mod:`harness.run.spec`) accepts no other keys.  Exit status
(:attr:`NightlyOutcome.exit_code`): 0 no regression, 1 at least one regression, 3 no regression
but the report could not be built.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from harness.run.spec import load_campaign
from harness.run.campaign import CaseWork, run_campaign
from harness.store.compare import compare_runs
from harness.store.runs import RunStore, latest_run
from harness.common.numbers import format_number

#: Default campaign of ``mbh nightly``.
DEFAULT_CAMPAIGN = "nightly"
#: Default threshold: an ``ok`` case whose main-output error grew more than this many times.
ERROR_FACTOR = 10.0
#: Default threshold: an ``ok`` case whose calibrated wall time grew more than this many times.
TIME_FACTOR = 2.0
#: Change classes of :func:`harness.store.compare.compare_runs` that are regressions.
REGRESSIONS = ("newly failing", "less accurate", "slower")
#: Change classes reported as improvements in the summary.
IMPROVEMENTS = ("newly passing", "more accurate", "faster")
#: Name of the summary file in the run folder.
SUMMARY_FILE = "nightly_summary.md"
#: Folder of the reports in the run folder.
REPORT_FOLDER = "report"
#: Exit status when the report step failed and nothing regressed.
REPORT_FAILED = 3


def case_work(campaign):
    """The work function every case of a nightly runs (:class:`harness.run.campaign.CaseWork` with the
    campaign's bounds and accuracy).  Tests replace it (pytest ``monkeypatch``) to inject a
    regression; nothing else does."""
    return CaseWork(campaign.bounds, campaign.accuracy)


@dataclass
class NightlyOutcome:
    """What a nightly produced.

    Attributes
    ----------
    store : RunStore
        This run.
    previous : str or None
        Run id compared against (None: no earlier complete run of the campaign).
    changes : DataFrame
        :func:`harness.store.compare.compare_runs` of the previous run → this one (empty without one).
    reports : dict
        Format → path written; empty when the report step was skipped or failed.
    report_note : str
        What happened in the report step.
    summary : str
        The Markdown summary.
    summary_path : Path
    """

    store: RunStore
    previous: str | None
    changes: pd.DataFrame
    reports: dict
    report_note: str
    summary: str
    summary_path: Path

    @property
    def regressions(self) -> pd.DataFrame:
        """The rows of :attr:`changes` that are :data:`REGRESSIONS`."""
        return regressions_of(self.changes)

    @property
    def exit_code(self) -> int:
        if len(self.regressions):
            return 1
        return REPORT_FAILED if self.report_note.startswith("report failed") else 0


def regressions_of(changes: pd.DataFrame) -> pd.DataFrame:
    """The rows of a :func:`harness.store.compare.compare_runs` table that are :data:`REGRESSIONS`."""
    return changes[changes["change"].isin(REGRESSIONS)]


def build_reports(store: RunStore, previous: str | None, root, formats) -> tuple[dict, str]:
    """The run's reports in ``<run folder>/report/``, and a note on what happened.

    Skipped with a note when :mod:`harness.report.build` is not installed or ``formats`` is
    empty; a failing build is a note beginning ``"report failed"`` (the run stays stored).
    """
    if not formats:
        return {}, "report skipped (--no-report)"
    try:
        from harness.report.build import build_report
    except ImportError as error:
        return {}, f"report skipped: harness.report.build is not available ({error})"
    try:
        written = build_report(store.run_id, against=previous, formats=formats,
                               out=store.path / REPORT_FOLDER, root=root)
    except Exception as error:  # noqa: BLE001 — any failure of the report is reported, not fatal
        return {}, f"report failed: {type(error).__name__}: {error}"
    return written, "report written: " + ", ".join(str(p) for p in written.values())


def regression_lines(changes: pd.DataFrame) -> list[str]:
    """One Markdown table row per regression: case, change, statuses, error and time ratios
    (the ``|`` of case ids escaped, as tables need)."""
    lines = []
    for row in changes.itertuples(index=False):
        case = row.case_id.replace("|", "\\|")
        lines.append(f"| `{case}` | {row.change} | {row.status_a} → {row.status_b} | "
                     f"{format_number(row.main_output_error_a)} → "
                     f"{format_number(row.main_output_error_b)} "
                     f"(×{format_number(row.error_ratio)}) | ×{format_number(row.time_ratio)} |")
    return lines


def summary_markdown(outcome_store: RunStore, previous: str | None, changes: pd.DataFrame,
                     regressions: pd.DataFrame, report_note: str, seconds: float,
                     error_factor: float, time_factor: float) -> str:
    """The nightly's Markdown summary (see the module docstring)."""
    cases = outcome_store.cases()
    counts = ", ".join(f"{status} {count}"
                       for status, count in sorted(cases["status"].value_counts().items()))
    calibration = outcome_store.calibration_s
    lines = [f"## mbh nightly: {outcome_store.run_id}", "",
             f"Campaign `{outcome_store.manifest['campaign']}`: {len(cases)} cases ({counts}) "
             f"in {seconds:.0f} s; calibration case "
             + (f"{calibration:.3g} s." if calibration else "not timed (no machine-speed "
                                                            "figure)."), ""]
    if previous is None:
        lines.append("No earlier complete run of this campaign under this results root: "
                     "nothing to compare, no regression possible.")
    else:
        found = changes["change"].value_counts()
        tally = ", ".join(f"{change} {int(found.get(change, 0))}"
                          for change in (*REGRESSIONS, *IMPROVEMENTS))
        lines += [f"Compared with `{previous}`: {len(changes)} cases in both runs; {tally} "
                  f"(thresholds: error ×{error_factor:g}, calibrated time ×{time_factor:g}).", ""]
        if len(regressions):
            lines += [f"**{len(regressions)} regression(s):**", "",
                      "| case | change | status | main-output error | calibrated time |",
                      "|---|---|---|---|---|", *regression_lines(regressions)]
        else:
            lines.append("**No regression.**")
    lines += ["", f"Run folder: `{outcome_store.path}`; {report_note}."]
    return "\n".join(lines) + "\n"


def nightly(campaign_name: str = DEFAULT_CAMPAIGN, *, root=None, workers: int | None = None,
            error_factor: float = ERROR_FACTOR, time_factor: float = TIME_FACTOR,
            summary_path=None, formats=("html", "pdf"), quiet: bool = False) -> NightlyOutcome:
    """Run, compare, report and summarise (see the module docstring).

    Parameters
    ----------
    campaign_name : str
        Shipped campaign name or campaign file.
    root : path, optional
        Results root (default :func:`harness.store.runs.results_root`).
    workers : int, optional
        Local worker processes (default: the cores).
    error_factor, time_factor : float
        Regression thresholds (> 1).
    summary_path : path, optional
        Markdown summary file (default ``<run folder>/nightly_summary.md``).
    formats : iterable of str
        Report formats (empty: no report).
    quiet : bool
        No progress bar.

    Raises
    ------
    harness.run.spec.CampaignError, harness.run.campaign.RunnerError, ValueError
        A campaign file with mistakes, a run that cannot start, thresholds not above 1.
    """
    for name, value in (("error factor", error_factor), ("time factor", time_factor)):
        if not value > 1:
            raise ValueError(f"the {name} must be above 1, got {value!r}")
    campaign = load_campaign(campaign_name)
    previous = latest_run(campaign.name, root, statuses=("complete",))
    started = time.monotonic()
    store = run_campaign(campaign, workers=workers, root=root, quiet=quiet,
                         work=case_work(campaign))
    seconds = time.monotonic() - started
    if previous is None:
        changes = pd.DataFrame(columns=["case_id", "change"])
    else:
        before = RunStore.open(previous, root)
        changes = compare_runs(before.cases(), store.cases(), before.calibration_s,
                               store.calibration_s, error_factor=error_factor,
                               time_factor=time_factor)
    reports, note = build_reports(store, previous, root, tuple(formats))
    summary = summary_markdown(store, previous, changes, regressions_of(changes), note, seconds,
                               error_factor, time_factor)
    path = Path(summary_path) if summary_path else store.path / SUMMARY_FILE
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(summary, encoding="utf-8")
    step_summary = os.environ.get("GITHUB_STEP_SUMMARY")
    if step_summary:
        with open(step_summary, "a", encoding="utf-8") as file:
            file.write(summary)
    return NightlyOutcome(store, previous, changes, reports, note, summary, path)
