"""Build a run's report: collect everything from the stored run into a :class:`Report`, then write
it as one self-contained HTML file (:func:`render_html`) and/or a PDF (:mod:`mbh._harness.report.pdf`).

Only stored results are read (:class:`mbh._harness.store.runs.RunStore`: case rows, sweeps, trajectories,
the manifest) plus the seed table stored beside the run (:mod:`mbh._harness.report.seed_compare`);
nothing is re-run.  Drawings of a mechanism need its scenario file as it was when the run was
made: a scenario whose content hash differs from the run's manifest (or that no longer loads) is
drawn nowhere, and the report says so.  References come from the reference cache the run filled.

The output depends only on the stored run, the previous run compared against and the build
timestamp (``SOURCE_DATE_EPOCH`` fixes it, as in reproducible builds), so two builds can be
diffed.
"""

from __future__ import annotations

import datetime as _dt
import os
import shlex
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import jinja2
import numpy as np
import pandas as pd

from mbh._harness.common.status import CaseStatus
from mbh._harness.model import scenario as scenarios
from mbh._harness.store.reference_files import stored_reference
from mbh._harness.report import coordinates, failures, figures, mechanism, seed_compare, summary
from mbh._harness.report.summary import Table
from mbh._harness.model.scenario import ScenarioError
from mbh._harness.measure.verdict import DEFAULT_ACCURACY
from mbh._harness.store.compare import comparable_calibrations, compare_runs
from mbh._harness.store.location import root_or_default
from mbh._harness.store.manifest import latest_run
from mbh._harness.store.rerun import campaign_argument
from mbh._harness.store.runs import RunStore
from mbh._harness.common.errors import MbhError

#: Output formats :func:`build_report` writes.
FORMATS = ("html", "pdf")

#: Outputs drawn on the work-precision diagrams' y axis: column → what it is.
WORK_PRECISION_OUTPUTS = {
    "main_output_error": "main-output error",
    "max_constraint_violation": "constraint violation",
    "max_energy_error_rel": "energy error",
}

#: Instants of the mechanism pictures, as fractions of the drawn time span.
SNAPSHOT_FRACTIONS = (0.0, 1 / 3, 2 / 3, 1.0)

#: Frames of the HTML animation of each mechanism.
ANIMATION_FRAMES = 60

_TEMPLATES = Path(__file__).resolve().parent / "templates"


class ReportError(MbhError, ValueError):
    """A report that cannot be built as asked (unknown run, bad format); the message says why."""


@dataclass(frozen=True)
class MechanismView:
    """A scenario's mechanism drawn from stored body states."""

    scenario: str
    snapshots: figures.Figure
    animation: str


@dataclass
class Report:
    """Everything a report shows, in reading order (see the templates and :mod:`.pdf`)."""

    run_id: str
    campaign: str
    run_status: str
    against: str | None
    built_at: str
    command: str
    accuracy: float
    scenarios: list[str]
    fastest: list[Table]
    pareto: Table
    status_counts: Table
    failures: Table
    changes: Table | None
    work_precision: list[tuple[str, list[figures.Figure]]]
    stability: list[figures.Figure]
    histories: list[figures.Figure]
    model_size: Table
    coordinates: list[Table]
    mechanisms: list[MechanismView]
    seed: dict
    environment: list[tuple[str, str]]
    scenario_hashes: Table
    campaign_text: str
    cases: Table
    #: Section key → sentences on what the section leaves out and why.
    omitted: dict[str, list[str]] = field(default_factory=dict)
    #: "Where methods fail" (:mod:`.failures`): hard or swept scenes; empty: no such section.
    failure_scenes: list[failures.FailureScene] = field(default_factory=list)

    def omit(self, section: str, why: str) -> None:
        self.omitted.setdefault(section, []).append(why)


def reports_root(root: Path | None = None) -> Path:
    """Where ``mbh report`` and ``mbh history`` write by default: ``reports`` in the results root
    ``root`` (default :func:`~mbh._harness.store.location.results_root`: ``$MBH_RESULTS_DIR``,
    else ``results`` in a checkout, else in the user data folder)."""
    return root_or_default(root) / "reports"


def reproduce_commands(manifest: dict, against: str | None = None,
                       root: Path | None = None) -> str:
    """The commands that make the run of ``manifest`` again and build this report of it.

    The campaign is named as ``mbh run`` takes it
    (:func:`~mbh._harness.store.rerun.campaign_argument`); ``--root`` is added when the report
    was built from a results root given as one.
    """
    root_option = f" --root {shlex.quote(str(root))}" if root is not None else ""
    report = f"mbh report {manifest['run_id']}" + (f" --against {against}" if against else "")
    made = f"   # made run {manifest['run_id']}"
    return (f"mbh run {campaign_argument(manifest)}{root_option}{made}\n"
            f"{report}{root_option}")


def parse_formats(text: str) -> tuple[str, ...]:
    """``"html,pdf"`` → ``("html", "pdf")``.

    Raises
    ------
    ReportError
        For an empty list or a format not in :data:`FORMATS`.
    """
    formats = tuple(dict.fromkeys(part.strip().lower() for part in text.split(",") if part.strip()))
    unknown = [f for f in formats if f not in FORMATS]
    if not formats or unknown:
        raise ReportError(f"--format {text!r}: give one or more of {', '.join(FORMATS)} "
                          f"separated by commas" + (f" (unknown: {', '.join(unknown)})"
                                                    if unknown else ""))
    return formats


def build_time() -> str:
    """The build timestamp (UTC, ISO 8601): ``SOURCE_DATE_EPOCH`` when set, else now."""
    epoch = os.environ.get("SOURCE_DATE_EPOCH")
    moment = (_dt.datetime.fromtimestamp(int(epoch), _dt.timezone.utc) if epoch
              else _dt.datetime.now(_dt.timezone.utc))
    return moment.isoformat(timespec="seconds")


def _open(run_id: str, root) -> RunStore:
    try:
        return RunStore.open(run_id, root)
    except (FileNotFoundError, ValueError) as error:
        raise ReportError(str(error)) from None


def _campaign_accuracy(manifest: dict) -> float:
    """The run's accuracy threshold (rad or m) from the stored campaign file."""
    try:
        document = tomllib.loads(manifest.get("campaign_text") or "")
    except tomllib.TOMLDecodeError:
        return DEFAULT_ACCURACY
    return float(document.get("accuracy", DEFAULT_ACCURACY))


def _mechanism(name: str, manifest: dict, report: Report):
    """The scenario ``name`` as it was when the run was made, or None (noted in ``report``)."""
    try:
        mech = scenarios.load(name)
    except (ScenarioError, OSError) as error:
        report.omit("mechanisms", f"{name}: the scenario does not load now ({error}); nothing is "
                                  f"drawn from its body states.")
        return None
    stored = (manifest.get("scenario_hashes") or {}).get(name)
    if stored != mech.content_hash:
        report.omit("mechanisms", f"{name}: the scenario file changed since the run (content hash "
                                  f"{str(stored)[:12]} in the run, {mech.content_hash[:12]} now); "
                                  f"nothing is drawn from its body states.")
        return None
    return mech


def _reference(mech, report: Report):
    """``mech``'s stored reference, or None (noted in ``report``): a report never builds one."""
    reference = stored_reference(mech)
    if reference is None:
        report.omit("histories", f"{mech.name}: no verified reference is stored for it; its time "
                                 f"histories show the case alone.")
    return reference


def _trajectory(store: RunStore, row, report: Report, section: str):
    try:
        return store.trajectory(row["case_id"])
    except KeyError as error:
        report.omit(section, str(error.args[0]))
        return None


def _label(row) -> str:
    return f"{row['adapter']} {row['method']} dt={row['dt']:g}"


def _history_cases(cases: pd.DataFrame, accuracy: float) -> list[tuple[str, pd.Series]]:
    """The chosen cases of a scenario: the fastest reaching ``accuracy``, and of the cases that
    did not end ``ok`` the one that ran longest before failing (first stored on a tie)."""
    chosen = []
    hits = summary.reaching(cases, accuracy)
    if len(hits):
        chosen.append((f"fastest case within {accuracy:g}", hits.iloc[0]))
    failing = cases[(cases["status"] != CaseStatus.OK) & cases["trajectory_file"].notna()]
    if len(failing):
        longest = failing.iloc[int(np.argmax(failing["failure_time"].astype(float)
                                             .fillna(-np.inf).to_numpy()))]
        chosen.append((f"{longest['status']} case that ran longest", longest))
    return chosen


def _drawable(row, trajectory, report: Report) -> bool:
    """Whether ``trajectory`` has a time span to draw (else a note says why not)."""
    if len(trajectory.times) >= 2:
        return True
    stored = (f"at t = {float(trajectory.times[-1]):g} s with one stored sample"
              if len(trajectory.times) else "with no stored sample")
    report.omit("histories", f"{row['scenario']}: {_label(row)} ended {row['status']} {stored}; "
                             f"there is nothing to draw over time ({row['reason']}).")
    return False


def _overlay_cases(cases: pd.DataFrame) -> list[pd.Series]:
    """Per adapter, its most accurate ``ok`` case (the engines to overlay on a drawing)."""
    ok = cases[cases["status"] == CaseStatus.OK].copy()
    ok["_error"] = ok["main_output_error"].astype(float)
    best = ok.sort_values(["_error", "wall_time_s", "case_id"], kind="stable")
    return [group.iloc[0] for _, group in best.groupby("adapter", sort=True)]


def _draw_scenario(store: RunStore, name: str, cases: pd.DataFrame, accuracy: float,
                   report: Report) -> None:
    """Time histories and mechanism drawings of scenario ``name`` (what its data allows)."""
    mech = _mechanism(name, store.manifest, report)
    if mech is None:
        return
    reference = _reference(mech, report)
    for why, row in _history_cases(cases, accuracy):
        trajectory = _trajectory(store, row, report, "histories")
        if trajectory is not None and _drawable(row, trajectory, report):
            report.histories.append(figures.time_history(
                mech, trajectory, reference, f"{name}: {_label(row)} ({why})"))
    overlay = {}
    for row in _overlay_cases(cases):
        trajectory = _trajectory(store, row, report, "mechanisms")
        if trajectory is not None:
            overlay[_label(row)] = trajectory
    if reference is not None:
        overlay["reference"] = reference
    if not overlay:
        report.omit("mechanisms", f"{name}: no ok case with a stored trajectory to draw.")
        return
    span = min(float(t.times[-1]) for t in overlay.values())
    times = [round(span * fraction, 6) for fraction in SNAPSHOT_FRACTIONS]
    report.mechanisms.append(MechanismView(
        name, mechanism.mechanism_snapshots(mech, overlay, times),
        mechanism.mechanism_animation(mech, overlay, frames=ANIMATION_FRAMES)))


def _environment(manifest: dict) -> list[tuple[str, str]]:
    git = manifest.get("git") or {}
    rows = [("run", manifest["run_id"]), ("campaign", manifest.get("campaign", "")),
            ("status", manifest.get("status", "")), ("started", str(manifest.get("started"))),
            ("ended", str(manifest.get("ended"))),
            ("git commit", f"{git.get('commit')} ({'dirty' if git.get('dirty') else 'clean'})"),
            ("calibration case wall time (s)", summary.cell_text(manifest.get("calibration_s"))),
            ("schema version", str(manifest.get("schema_version")))]
    rows += [(f"machine: {key}", str(value)) for key, value in (manifest.get("machine") or {}).items()]
    rows += [(f"package: {name}", str(version))
             for name, version in (manifest.get("packages") or {}).items()]
    return rows


def _seed_section(store: RunStore) -> dict:
    published = seed_compare.load_published()
    section = {"source": published["source"], "notes": seed_compare.NOTES,
               "remarks": [r["text"] for r in published.get("remarks", [])],
               "file": seed_compare.SEED_TABLE_FILE, "table": None, "newton": None,
               "summary": [], "missing": None}
    try:
        ours = seed_compare.load_ours(store.path)
    except seed_compare.SeedTableError as error:
        ours, section["missing"] = None, f"{error}. Only the published figures are listed."
    if ours is None and section["missing"] is None:
        section["missing"] = (f"This run has no seed table ({seed_compare.SEED_TABLE_FILE} beside "
                              f"the run is missing; `make report` writes it with `mbh seed-table "
                              f"--json`). Only the published figures are listed.")
    table = seed_compare.comparison_table(published, ours or [])
    section.update(table=table, newton=seed_compare.newton_table(published, ours or []),
                   summary=seed_compare.ratio_summary(table) if ours else [])
    return section


def _hashes_table(manifest: dict) -> Table:
    hashes = manifest.get("scenario_hashes") or {}
    return Table(key="scenario-hashes", caption="Scenario content hashes of the run",
                 columns=("scenario", "content hash"), rows=tuple(sorted(hashes.items())))


def collect(run_id: str, against: str | None = None, root: Path | None = None,
            built_at: str | None = None) -> Report:
    """Everything the report of run ``run_id`` shows (compared with run ``against``).

    Raises
    ------
    ReportError
        When either run does not exist or cannot be read.
    """
    store = _open(run_id, root)
    previous = _open(against, root) if against else None
    manifest = store.manifest
    cases = store.cases()
    sweeps = store.sweeps()
    accuracy = _campaign_accuracy(manifest)
    calibration = store.calibration_s
    names = sorted(cases["scenario"].dropna().unique()) if len(cases) else []
    report = Report(
        run_id=run_id, campaign=manifest.get("campaign", ""), run_status=manifest.get("status", ""),
        against=against, built_at=built_at or build_time(),
        command=reproduce_commands(manifest, against, root),
        accuracy=accuracy, scenarios=names,
        fastest=[summary.fastest_table(cases, name, calibration) for name in names]
        + [summary.front_ratio_table(cases, name) for name in names if _has_front(cases, name)],
        pareto=summary.pareto_table(cases),
        status_counts=summary.status_counts_table(cases), failures=summary.failures_table(cases),
        changes=None, work_precision=[], stability=[], histories=[],
        model_size=summary.model_size_table(cases, accuracy),
        coordinates=[table for table in (coordinates.coordinates_table(cases, name)
                                         for name in names) if table is not None],
        mechanisms=[],
        seed=_seed_section(store), environment=_environment(manifest),
        scenario_hashes=_hashes_table(manifest), campaign_text=manifest.get("campaign_text") or "",
        cases=summary.cases_table(cases, calibration))
    if previous is None:
        report.omit("changes", "No previous run to compare with (none given with --against, or "
                               "no earlier finished run of the same campaign).")
    else:
        report.changes = summary.changes_table(compare_runs(
            previous.cases(), cases, *comparable_calibrations(previous, store)))
    for name in names:
        mine = cases[cases["scenario"] == name]
        report.work_precision.append(
            (name, [figures.work_precision(cases, name, y=y) for y in WORK_PRECISION_OUTPUTS]))
        report.stability.append(figures.stability_map(cases, sweeps, name, accuracy))
        _draw_scenario(store, name, mine, accuracy, report)
    report.failure_scenes = failures.section_scenes(
        cases, sweeps, accuracy, manifest, lambda why: report.omit("failures", why))
    for problem in store.problems:  # damaged files of the run (docs/formats/store.md)
        report.omit("store", f"Damaged stored file, left out of this report: {problem}")
    return report


def _environment_for_template():
    environment = jinja2.Environment(
        loader=jinja2.FileSystemLoader(_TEMPLATES), autoescape=True,
        undefined=jinja2.StrictUndefined, trim_blocks=True, lstrip_blocks=True)
    environment.filters["cell"] = summary.cell_text
    environment.filters["sortkey"] = _sort_attribute
    environment.filters["inline_svg"] = inline_svg
    return environment


def _sort_attribute(value) -> str:
    key = summary.sort_key(value)
    return "" if key is None or not np.isfinite(key) else repr(key)


def inline_svg(svg: str) -> str:
    """``svg`` ready to sit inside HTML: everything before the ``<svg`` element (XML
    declaration, DOCTYPE, comments) removed.  The SVG text itself comes from matplotlib, which
    escapes every text it writes."""
    start = svg.find("<svg")
    if start < 0:
        raise ValueError("figure SVG has no <svg> element")
    return svg[start:]


def render_html(report: Report) -> str:
    """The report as one self-contained HTML document (no external fetches)."""
    template = _environment_for_template().get_template("report.html.j2")
    return template.render(report=report, levels=summary.ACCURACY_LEVELS,
                           wp_outputs=WORK_PRECISION_OUTPUTS, css=_asset("report.css"),
                           js=_asset("report.js"))


def _asset(name: str) -> str:
    return (_TEMPLATES / name).read_text(encoding="utf-8")


def _has_front(cases, scenario: str) -> bool:
    """Whether the run has both in-house and engine cases on ``scenario`` to set side by side."""
    adapters = set(cases.loc[cases["scenario"] == scenario, "adapter"])
    return summary.INHOUSE in adapters and len(adapters) > 1


def build_report(run_id: str, against: str | None = None, formats=FORMATS,
                 out: Path | None = None, root: Path | None = None,
                 built_at: str | None = None) -> dict[str, Path]:
    """Write the report of run ``run_id`` into ``out`` (default ``<root>/reports/<run_id>/``,
    :func:`reports_root`).

    Parameters
    ----------
    run_id, against : str
        The run, and the previous run to compare with (None: no comparison; ``"previous"``:
        :func:`mbh._harness.store.runs.latest_run` of the campaign before ``run_id``).
    formats : iterable of str
        Any of :data:`FORMATS`.
    out, root : Path, optional
        Output folder and results root.
    built_at : str, optional
        Build timestamp to print (default :func:`build_time`).

    Returns
    -------
    dict
        Format → path written (``report.html``, ``report.pdf``).
    """
    formats = tuple(formats)
    if against == "previous":
        campaign = _open(run_id, root).manifest["campaign"]
        against = latest_run(campaign, root, before=run_id)
    report = collect(run_id, against, root, built_at)
    out = Path(out) if out is not None else reports_root(root) / run_id
    out.mkdir(parents=True, exist_ok=True)
    written = {}
    if "pdf" in formats:
        from mbh._harness.report.pdf import render_pdf

        written["pdf"] = out / "report.pdf"
        written["pdf"].write_bytes(render_pdf(report))
    if "html" in formats:
        written["html"] = out / "report.html"
        written["html"].write_text(render_html(report), encoding="utf-8")
    return written
