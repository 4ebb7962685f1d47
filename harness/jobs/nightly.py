"""``mbh nightly``: run a campaign, gate on the steps in its history (or on the previous run),
build its reports and the history page, and summarise.

Steps of :func:`nightly`:

1. the previous run: the latest ``complete`` run of the same campaign (by name) under the results
   root, looked up before this run starts;
2. the campaign runs into the store (:func:`mbh._harness.run.campaign.run_campaign`, calibration case
   included);
3. the two runs are compared case by case (:func:`mbh._harness.store.compare.compare_runs`: errors as
   ratios, wall times as ratios of calibrated times, i.e. each divided by its own run's
   calibration case);
4. the campaign's history (every finished run of it, this one included) is searched for steps
   (:func:`mbh._harness.report.history.find_changes`);
5. the reports are built into ``<run folder>/report/``: the run's report (``report.html``,
   ``report.pdf``) when :mod:`mbh._harness.report.build` is installed, and the history page
   (``history.html``) linking to every run's report (otherwise the step is skipped with a note);
6. the gate's record ``<run folder>/nightly_gate.json`` (the regressions open after this run)
   and a short summary, printed and written as Markdown (``<run folder>/nightly_summary.md``
   unless given, and appended to ``$GITHUB_STEP_SUMMARY`` when that is set).

The gate (``gate``):

* ``"history"`` (default): a regression is a step for the worse in a case's history that is still
  open at this run (:func:`mbh._harness.report.history.open_regressions`: newly not ``ok``, an error
  grown at least ×2, a calibrated time grown at least ×1.1 beyond its measured noise and seen on
  two runs) and that no earlier nightly's record lists as open: each regression fails one night,
  then stays listed as "still open" until the case is back at its level.  The summary lists what
  changed since the last good run (the latest earlier nightly whose gate passed).
* ``"previous"``: a regression is a case present in both this run and the previous one that is
  :data:`REGRESSIONS`: newly failing (``ok`` before, not ``ok`` now), less accurate (main output
  error more than ``error_factor`` times the previous one) or slower (calibrated time more than
  ``time_factor`` times the previous one).

The thresholds are command-line options: the campaign file format (:mod:`mbh._harness.run.spec`)
accepts no other keys.  Exit status (:attr:`NightlyOutcome.exit_code`): 0 no regression, 1 at
least one regression (by the chosen gate), 3 no regression but the report or the history page
could not be built.
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from mbh._harness.run.spec import load_campaign
from mbh._harness.run.campaign import run_campaign
from mbh._harness.run.row import CaseWork
from mbh._harness.report.history import (QUANTITIES, STATUS, find_changes, load_history,
                                    open_regressions)
from mbh._harness.store.compare import comparable_calibrations, compare_runs
from mbh._harness.common.status import RunStatus
from mbh._harness.store.manifest import latest_run, list_runs
from mbh._harness.store.runs import RunStore
from mbh._harness.common.numbers import format_number

#: Default campaign of ``mbh nightly``.
DEFAULT_CAMPAIGN = "nightly"
#: The gates: on the steps of the campaign's history, or on the previous run alone.
GATES = ("history", "previous")
DEFAULT_GATE = "history"
#: Default threshold of the previous-run gate: an ``ok`` case whose main-output error grew more
#: than this many times.
ERROR_FACTOR = 10.0
#: Default threshold of the previous-run gate: an ``ok`` case whose calibrated wall time grew
#: more than this many times.
TIME_FACTOR = 2.0
#: Change classes of :func:`mbh._harness.store.compare.compare_runs` that are regressions.
REGRESSIONS = ("newly failing", "less accurate", "slower")
#: Change classes reported as improvements in the summary.
IMPROVEMENTS = ("newly passing", "more accurate", "faster")
#: Name of the summary file in the run folder.
SUMMARY_FILE = "nightly_summary.md"
#: Name of the gate's record in the run folder: the gate, whether it passed, the open regressions.
GATE_FILE = "nightly_gate.json"
#: Folder of the reports (and the history page) in the run folder.
REPORT_FOLDER = "report"
#: Exit status when the report step failed and nothing regressed.
REPORT_FAILED = 3
#: How the report step's note begins when it failed.
FAILED_NOTES = ("report failed", "history page failed")
#: Most change lines of each list in the summary (the history page has them all).
SUMMARY_LINES = 30


def case_work(campaign):
    """The work function every case of a nightly runs (:class:`mbh._harness.run.row.CaseWork` with the
    campaign's bounds and accuracy).  Tests replace it (pytest ``monkeypatch``) to inject a
    regression; nothing else does."""
    return CaseWork(campaign.bounds, campaign.accuracy)


@dataclass
class HistoryGate:
    """What the history says after this run.

    Attributes
    ----------
    changes : DataFrame
        :func:`mbh._harness.report.history.find_changes` over every finished run of the campaign.
    new : DataFrame
        Open regressions no earlier nightly's record lists (what fails the history gate).
    still_open : DataFrame
        Open regressions an earlier nightly already reported.
    last_good : str or None
        The latest earlier nightly run whose gate passed.
    since_last_good : DataFrame
        The changes whose first run came after ``last_good`` (all of them without one).
    """

    changes: pd.DataFrame
    new: pd.DataFrame
    still_open: pd.DataFrame
    last_good: str | None
    since_last_good: pd.DataFrame


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
        :func:`mbh._harness.store.compare.compare_runs` of the previous run → this one (empty without one).
    history : HistoryGate
    gate : str
        One of :data:`GATES`.
    reports : dict
        ``"html"``, ``"pdf"``, ``"history"`` → path written; empty when the report step was
        skipped or failed.
    report_note : str
        What happened in the report step.
    summary : str
        The Markdown summary.
    summary_path : Path
    """

    store: RunStore
    previous: str | None
    changes: pd.DataFrame
    history: HistoryGate
    gate: str
    reports: dict
    report_note: str
    summary: str
    summary_path: Path

    @property
    def regressions(self) -> pd.DataFrame:
        """What fails the gate: the new open regressions of the history, or the rows of
        :attr:`changes` that are :data:`REGRESSIONS`."""
        return self.history.new if self.gate == "history" else regressions_of(self.changes)

    @property
    def exit_code(self) -> int:
        if len(self.regressions):
            return 1
        return REPORT_FAILED if self.report_note.startswith(FAILED_NOTES) else 0


def regressions_of(changes: pd.DataFrame) -> pd.DataFrame:
    """The rows of a :func:`mbh._harness.store.compare.compare_runs` table that are :data:`REGRESSIONS`."""
    return changes[changes["change"].isin(REGRESSIONS)]


def regression_keys(changes: pd.DataFrame) -> pd.Series:
    """How a gate record names each regression of ``changes``: ``CASE_ID|QUANTITY`` (stable when
    later runs move the step's estimated first run)."""
    return changes["case_id"] + "|" + changes["quantity"]


def _earlier_records(store: RunStore, root) -> list[tuple[str, dict]]:
    """(run id, gate record) of the earlier runs of this campaign that have a readable record,
    newest first."""
    mine = store.manifest
    records = []
    for manifest in reversed(list_runs(root)):
        if manifest["campaign"] != mine["campaign"] or manifest["started"] >= mine["started"]:
            continue
        try:
            record = json.loads((store.path.parent / manifest["run_id"] / GATE_FILE)
                                .read_text(encoding="utf-8"))
        except (OSError, ValueError):  # no record (not a nightly) or a damaged one
            continue
        if isinstance(record, dict):
            records.append((manifest["run_id"], record))
    return records


def history_gate(store: RunStore, root) -> HistoryGate:
    """The history of this run's campaign, judged against the earlier nightlies' records."""
    history = load_history(store.manifest["campaign"], root)
    changes = find_changes(history)
    open_now = open_regressions(changes)
    records = _earlier_records(store, root)
    known = set(records[0][1].get("open", [])) if records else set()
    last_good = next((run for run, record in records if record.get("passed")), None)
    is_known = regression_keys(open_now).isin(known)
    new, still_open = open_now[~is_known], open_now[is_known]
    runs = history.runs["run_id"].tolist()
    since = changes[changes["run"] > runs.index(last_good)] if last_good in runs else changes
    return HistoryGate(changes, new, still_open, last_good, since)


def write_gate_record(store: RunStore, gate: str, passed: bool, history: HistoryGate) -> None:
    """``<run folder>/nightly_gate.json``: the gate, whether it passed, the open regressions."""
    record = {"gate": gate, "passed": passed,
              "open": sorted([*regression_keys(history.new),
                              *regression_keys(history.still_open)])}
    (store.path / GATE_FILE).write_text(json.dumps(record, indent=1), encoding="utf-8")


def build_reports(store: RunStore, previous: str | None, root, formats,
                  history: HistoryGate | None = None) -> tuple[dict, str]:
    """The run's reports and the history page in ``<run folder>/report/``, and a note on what
    happened.

    Skipped with a note when :mod:`mbh._harness.report.build` is not installed or ``formats`` is
    empty; a failing build is a note beginning with one of :data:`FAILED_NOTES` (the run stays
    stored).
    """
    if not formats:
        return {}, "report skipped (--no-report)"
    try:
        from mbh._harness.report.build import build_report
        from mbh._harness.report.history_page import build_history
    except ImportError as error:
        return {}, f"report skipped: mbh._harness.report.build is not available ({error})"
    folder = store.path / REPORT_FOLDER
    try:
        written = build_report(store.run_id, against=previous, formats=formats, out=folder,
                               root=root)
    except Exception as error:  # noqa: BLE001 — any failure of the report is reported, not fatal
        return {}, f"report failed: {type(error).__name__}: {error}"
    try:
        written["history"] = build_history(store.manifest["campaign"], root, folder,
                                           changes=None if history is None else history.changes)
    except Exception as error:  # noqa: BLE001 — as the report's
        return written, f"history page failed: {type(error).__name__}: {error}"
    return written, "report written: " + ", ".join(str(p) for p in written.values())


def regression_lines(changes: pd.DataFrame) -> list[str]:
    """One Markdown table row per regression of the previous-run comparison: case, change,
    statuses, error and time ratios (the ``|`` of case ids escaped, as tables need)."""
    lines = []
    for row in changes.itertuples(index=False):
        case = row.case_id.replace("|", "\\|")
        lines.append(f"| `{case}` | {row.change} | {row.status_a} → {row.status_b} | "
                     f"{format_number(row.main_output_error_a)} → "
                     f"{format_number(row.main_output_error_b)} "
                     f"(×{format_number(row.error_ratio)}) | ×{format_number(row.time_ratio)} |")
    return lines


def history_lines(changes: pd.DataFrame, limit: int = SUMMARY_LINES) -> list[str]:
    """A Markdown table of history changes: case, change, quantity, first run (commit), engine
    version change, before → after (size), confidence; at most ``limit`` rows, then a count."""
    lines = ["| case | change | quantity | first run | before → after | confidence |",
             "|---|---|---|---|---|---|"]
    for row in changes.head(limit).itertuples(index=False):
        case = row.case_id.replace("|", "\\|")
        what = STATUS if row.quantity == STATUS else QUANTITIES[row.quantity][0]
        levels = (f"{row.before} → {row.after}" if row.quantity == STATUS else
                  f"{format_number(row.before)} → {format_number(row.after)} "
                  f"(×{format_number(row.factor)})")
        upgrade = f", {row.version_change}" if row.version_change else ""
        lines.append(f"| `{case}` | {row.kind} | {what} | `{row.run_id}` ({row.commit}{upgrade}) "
                     f"| {levels} | {row.confidence:.3g} |")
    if len(changes) > limit:
        lines.append(f"\n… and {len(changes) - limit} more on the history page.")
    return lines


def _previous_section(previous: str | None, changes: pd.DataFrame, gate: str,
                      error_factor: float, time_factor: float) -> list[str]:
    if previous is None:
        return ["No earlier complete run of this campaign under this results root: "
                "nothing to compare, no regression possible."]
    found = changes["change"].value_counts()
    tally = ", ".join(f"{change} {int(found.get(change, 0))}"
                      for change in (*REGRESSIONS, *IMPROVEMENTS))
    lines = [f"Compared with `{previous}`: {len(changes)} cases in both runs; {tally} "
             f"(thresholds: error ×{error_factor:g}, calibrated time ×{time_factor:g}).", ""]
    if gate != "previous":
        return lines
    regressions = regressions_of(changes)
    if len(regressions):
        return lines + [f"**{len(regressions)} regression(s):**", "",
                        "| case | change | status | main-output error | calibrated time |",
                        "|---|---|---|---|---|", *regression_lines(regressions)]
    return lines + ["**No regression.**"]


def _history_section(history: HistoryGate, gate: str) -> list[str]:
    counts = history.changes["kind"].value_counts()
    lines = [f"History: {int(counts.get('regression', 0))} regression(s) and "
             f"{int(counts.get('improvement', 0))} improvement(s) found over the campaign's "
             f"runs; {len(history.new) + len(history.still_open)} regression(s) open, "
             f"{len(history.new)} of them new.", ""]
    if gate != "history":  # the previous-run gate's summary lists the history's counts only
        return lines[:1]
    lines += ([f"**{len(history.new)} new regression(s):**", "", *history_lines(history.new),
               ""] if len(history.new) else ["**No new regression.**", ""])
    if len(history.still_open):
        lines += ["Still open, reported by an earlier nightly:", "",
                  *history_lines(history.still_open), ""]
    since = (f"since the last good run `{history.last_good}`" if history.last_good
             else "over the whole history (no earlier nightly passed its gate)")
    lines += [f"Changed {since}: {len(history.since_last_good)}."]
    if len(history.since_last_good):
        lines += ["", *history_lines(history.since_last_good)]
    return lines


def summary_markdown(outcome_store: RunStore, previous: str | None, changes: pd.DataFrame,
                     history: HistoryGate, gate: str, report_note: str, seconds: float,
                     error_factor: float, time_factor: float, reports: dict) -> str:
    """The nightly's Markdown summary (see the module docstring)."""
    cases = outcome_store.cases()
    counts = ", ".join(f"{status} {count}"
                       for status, count in sorted(cases["status"].value_counts().items()))
    calibration = outcome_store.calibration_s
    lines = [f"## mbh nightly: {outcome_store.run_id}", "",
             f"Campaign `{outcome_store.manifest['campaign']}`: {len(cases)} cases ({counts}) "
             f"in {seconds:.0f} s; calibration case "
             + (f"{calibration:.3g} s." if calibration else "not timed (no machine-speed "
                                                            "figure).")
             + f" Gate: {gate}.", ""]
    lines += _previous_section(previous, changes, gate, error_factor, time_factor)
    lines += ["", *_history_section(history, gate)]
    if "history" in reports:
        lines += ["", f"History page: `{reports['history']}`."]
    lines += ["", f"Run folder: `{outcome_store.path}`; {report_note}."]
    return "\n".join(lines) + "\n"


def nightly(campaign_name: str = DEFAULT_CAMPAIGN, *, root=None, workers: int | None = None,
            gate: str = DEFAULT_GATE, error_factor: float = ERROR_FACTOR,
            time_factor: float = TIME_FACTOR, summary_path=None, formats=("html", "pdf"),
            quiet: bool = False) -> NightlyOutcome:
    """Run, compare, search the history, report and summarise (see the module docstring).

    Parameters
    ----------
    campaign_name : str
        Shipped campaign name or campaign file.
    root : path, optional
        Results root (default :func:`mbh._harness.store.location.results_root`).
    workers : int, optional
        Local worker processes (default: the cores).
    gate : str
        One of :data:`GATES`.
    error_factor, time_factor : float
        Thresholds of the previous-run comparison (> 1).
    summary_path : path, optional
        Markdown summary file (default ``<run folder>/nightly_summary.md``).
    formats : iterable of str
        Report formats (empty: no report and no history page).
    quiet : bool
        No progress bar.

    Raises
    ------
    mbh._harness.run.spec.CampaignError, mbh._harness.run.campaign.RunnerError, ValueError
        A campaign file with mistakes, a run that cannot start, thresholds not above 1, an
        unknown gate.
    """
    if gate not in GATES:
        raise ValueError(f"the gate must be one of {', '.join(GATES)}, got {gate!r}")
    for name, value in (("error factor", error_factor), ("time factor", time_factor)):
        if not value > 1:
            raise ValueError(f"the {name} must be above 1, got {value!r}")
    campaign = load_campaign(campaign_name)
    previous = latest_run(campaign.name, root, statuses=(RunStatus.COMPLETE,))
    started = time.monotonic()
    store = run_campaign(campaign, workers=workers, root=root, quiet=quiet,
                         work=case_work(campaign))
    seconds = time.monotonic() - started
    if previous is None:
        changes = pd.DataFrame(columns=["case_id", "change"])
    else:
        before = RunStore.open(previous, root)
        changes = compare_runs(before.cases(), store.cases(),
                               *comparable_calibrations(before, store), error_factor=error_factor,
                               time_factor=time_factor)
    history = history_gate(store, root)
    reports, note = build_reports(store, previous, root, tuple(formats), history)
    summary = summary_markdown(store, previous, changes, history, gate, note, seconds,
                               error_factor, time_factor, reports)
    outcome = NightlyOutcome(store, previous, changes, history, gate, reports, note, summary,
                             Path(summary_path) if summary_path else store.path / SUMMARY_FILE)
    write_gate_record(store, gate, not len(outcome.regressions), history)
    outcome.summary_path.parent.mkdir(parents=True, exist_ok=True)
    outcome.summary_path.write_text(summary, encoding="utf-8")
    step_summary = os.environ.get("GITHUB_STEP_SUMMARY")
    if step_summary:
        with open(step_summary, "a", encoding="utf-8") as file:
            file.write(summary)
    return outcome
