"""The ``mbh`` command line.

Every user error (bad scenario file, unknown method, a step that does not fit the sample grid, a
mechanism that cannot be assembled) prints one clear message per problem on stderr and exits with
status 2; it never shows a traceback.

``--json`` output is strict JSON (RFC 8259), whatever the numbers: a non-finite value is written as
one of the strings ``"NaN"``, ``"Infinity"``, ``"-Infinity"`` (:mod:`mbh._harness.common.jsonout`), and what
an engine library prints while a case runs is captured at the file-descriptor level and kept in
the case's ``notes``, never on stdout (:mod:`mbh._harness.common.capture`).
"""

from __future__ import annotations

import argparse
import signal
import sys
import time

from mbh._harness.common import capture, jsonout, waits
from mbh._harness.common.errors import MbhError
from mbh._harness.common.numbers import format_number

from mbh._harness.model import scenario
from mbh._harness.model.scenario import ScenarioError
from mbh._harness.measure.verdict import Bounds

#: Most steps ``mbh simulate`` will attempt (a run longer than this is an input error).
MAX_STEPS = 1e8
BOUNDS_HELP = ("the verdict's bounds as NAME=VALUE,...: gap (joint gap / mechanism size, default "
               "%(gap)g), orientation (rad, %(orientation)g), energy (energy error / energy scale, "
               "%(energy)g), branch (distance from the reference's branch / mechanism size, "
               "%(branch)g), trajectory (distance from the reference at the same time / mechanism "
               "size, and a body's turn from it in rad, %(trajectory)g); see harness/measure/verdict.py"
               % vars(Bounds()))
JSON_HELP = ('strict JSON on stdout; non-finite numbers as the strings "NaN", "Infinity", '
             '"-Infinity"')
QUIET_HELP = "no progress lines on stderr (what is being compiled or built, and how long)"


class UserError(MbhError):
    """A problem with the user's input; printed without a traceback."""


def _load(name: str):
    try:
        return scenario.load(name)
    except ScenarioError as error:
        raise UserError(str(error)) from None


def _print_json(value) -> None:
    print(jsonout.dumps(value))


def _print_table(rows: list[dict], columns: list[str]) -> None:
    widths = {c: max([len(c), *(len(str(r.get(c, ""))) for r in rows)]) for c in columns}
    print("  ".join(c.ljust(widths[c]) for c in columns))
    for row in rows:
        print("  ".join(str(row.get(c, "")).ljust(widths[c]) for c in columns))


def cmd_scenarios(args) -> int:
    rows = []
    for name in scenario.scenario_names():
        mech = _load(name)
        rows.append({"name": name, "kind": mech.kind, "bodies": len(mech.bodies),
                     "joints": ", ".join(f"{j.name}:{j.type}" for j in mech.joints),
                     "tags": ", ".join(mech.tags)})
    if args.json:
        _print_json(rows)
    else:
        _print_table(rows, ["name", "kind", "bodies", "joints", "tags"])
        if not rows:
            print(f"mbh: no scenario files in {scenario.SCENARIO_DIR}", file=sys.stderr)
    return 0


def _names(args) -> list[str]:
    if args.all == bool(args.name):
        raise UserError("give a scenario NAME or --all")
    return scenario.scenario_names() if args.all else [args.name]


def cmd_check(args) -> int:
    """Kinematic analysis by the harness's neutral kinematics (:mod:`mbh._harness.neutral.assembly`,
    :mod:`mbh._harness.neutral.mobility`): assembly residuals, rank, mobility, redundant equations, singularity.

    ``n_coordinates`` counts twist coordinates (6 per spatial body, 3 per planar body) and
    ``n_equations`` the joint rows (no driver, no normalisation rows);
    ``redundant_equation_labels`` names the rows the rank-revealing QR leaves over and
    ``dependent_equation_labels`` every row taking part in a dependency (any of which could be
    the one dropped: all 30 on Bricard's mechanism).  A start at a singular
    configuration (condition number above :data:`mbh._harness.neutral.mobility.CONDITION_LIMIT`, or rank lost) is
    refused: its entry has the ``error`` and, with the rank analysis there, a ``warning``.
    """
    from mbh._harness.neutral.assembly import AssemblyError, assemble

    mechanisms = [_load(name) for name in _names(args)]  # a bad file: exit 2 before any output
    results, failed = [], False
    for mech in mechanisms:
        head = {"scenario": mech.name, "kind": mech.kind, "n_bodies": len(mech.bodies)}
        try:
            assembly = assemble(mech)
        except AssemblyError as error:
            failed = True
            report = getattr(error, "report", None)
            results.append({"scenario": mech.name, "error": str(error)}
                           | ({} if report is None else report.fields()))
            continue
        results.append(head | assembly.report.fields() | {
            "assembly_residual": assembly.residual, "assembly_iterations": assembly.iterations,
            "velocity_residual": assembly.velocity_residual})
    if args.json:
        _print_json(results)
    else:
        for result in results:
            if "warning" in result:
                print(f"mbh: warning: {result['scenario']}: {result['warning']}", file=sys.stderr)
            print(f"== {result['scenario']}")
            for key, value in result.items():
                if key != "scenario":
                    print(f"  {key:28s} {value}")
    return 1 if failed else 0


def cmd_methods(args) -> int:
    adapter = _adapter(args.adapter)
    rows = [{"method": spec.name, "parameters": ", ".join(f"{k}={v}" for k, v in spec.params.items()),
             "description": spec.description} for spec in adapter.methods()]
    if args.json:
        _print_json(rows)
    else:
        print(f"{adapter.version()}: {len(rows)} methods")
        _print_table(rows, ["method", "parameters", "description"])
    return 0


def _adapter(name: str):
    from mbh._adapters import get_adapter

    try:
        return get_adapter(name)
    except (ValueError, ImportError) as error:  # unknown, or cannot be loaded
        raise UserError(str(error)) from None


def cmd_adapters(args) -> int:
    """The registered adapters (built-in and from the ``mbh.adapters`` entry points): origin,
    package version, engine version and method count; a row's ``problem`` says why an adapter
    cannot be used (and exit 1)."""
    from mbh._adapters import inventory

    rows = inventory()
    if args.json:
        _print_json(rows)
    else:
        _print_table([{key: "" if value is None else value for key, value in row.items()}
                      for row in rows], ["name", "origin", "package_version", "version", "methods",
                                         "problem"])
    return 1 if any(row["problem"] for row in rows) else 0


def _bounds(text: str | None) -> Bounds:
    try:
        return Bounds.parse(text or "")
    except ValueError as error:
        raise UserError(f"--bounds: {error}") from None


def cmd_simulate(args) -> int:
    from mbh._harness.run.case import run_case
    from mbh._harness.references.build import ReferenceBuildError, reference_trajectory

    mech = _load(args.name)
    adapter = _adapter(args.adapter)
    bounds = _bounds(args.bounds)
    t_end = mech.duration if args.t_end is None else args.t_end
    if not 0 < t_end <= mech.duration:
        raise UserError(f"--t-end must be in (0, {mech.duration:g}] s, got {t_end:g}")
    if not args.dt > 0:
        raise UserError(f"--dt must be > 0, got {args.dt:g}")
    if t_end / args.dt > MAX_STEPS:
        raise UserError(f"--dt {args.dt:g} s would take {t_end / args.dt:.3g} steps to "
                        f"{t_end:g} s (at most {MAX_STEPS:.0e}); give a larger step")
    try:
        adapter.method_spec(args.method)
    except ValueError as error:
        raise UserError(str(error)) from None
    reference = None
    if not args.no_reference:
        try:
            reference = reference_trajectory(mech)
        except ReferenceBuildError as error:
            print(f"mbh: no reference: {error}", file=sys.stderr)
    try:
        case = run_case(adapter, mech, args.method, args.dt, t_end, reference, bounds)
    except ValueError as error:  # a step or end time the sample grid or the adapter refuses
        raise UserError(f"--dt {args.dt:g}, --t-end {t_end:g}: {error}") from None
    result = {"scenario": mech.name, "adapter": adapter.name, "version": adapter.version(),
              "method": args.method, "dt": args.dt, "t_end": t_end, **case.metrics}
    if args.json:
        _print_json(result)
    else:
        for key, value in result.items():
            print(f"{key:28s} {value}")
    return 0


def cmd_reference(args) -> int:
    """Build (or find) a scene's verified reference ahead of its first case and say where it is,
    how well its two routes agree and what it cost; exit 1 when the build is refused."""
    from mbh._harness.references.build import ReferenceBuildError, load_or_build
    from mbh._harness.store.reference_files import reference_paths

    mech = _load(args.name)
    try:
        _, info = load_or_build(mech, show_progress=None if not args.quiet else False)
    except ReferenceBuildError as error:
        print(f"mbh: reference refused: {error}", file=sys.stderr)
        return 1
    data_path, info_path = reference_paths(mech)
    result = {"scenario": mech.name, "content_hash": mech.content_hash,
              "data": str(data_path), "metadata": str(info_path),
              "agreement": info["agreement"]["max"],
              "wall_time_s": sum(info[key]["wall_time_s"] for key in ("route_a_cost", "route_b_cost"))}
    if args.json:
        _print_json(result)
    else:
        for key, value in result.items():
            print(f"{key:14s} {value}")
    return 0


def cmd_warm_up(args) -> int:
    """Compile the in-house kernels and loops ahead of the first runs (mbh._harness.run.warm_up) and
    say what each case compiled and how long it took; a failed case is listed, not fatal."""
    from mbh._harness.run.executor import usable_cores
    from mbh._harness.run.warm_up import warm_up

    began = time.perf_counter()
    warmed = warm_up(args.jobs or usable_cores())
    rows = [{"scenario": w.case.scene, "method": w.case.method, "compiles": w.case.what,
             "wall_time_s": w.seconds, "problem": w.problem} for w in warmed]
    if args.json:
        _print_json(rows)
        return 0
    problems = [row for row in rows if row["problem"]]
    print(f"warmed up: {len(rows)} cases in {time.perf_counter() - began:.0f} s"
          f"{f', {len(problems)} failed' if problems else ''}")
    for row in problems:
        print(f"  {row['scenario']} {row['method']}: {row['problem']}")
    return 0


def cmd_export(args) -> int:
    mech = _load(args.name)
    adapter = _adapter(args.adapter)
    from mbh._adapters.base import UnsupportedCase

    try:
        text = adapter.export(mech)
    except UnsupportedCase as error:
        raise UserError(f"{mech.name}: {error}") from None
    if args.output:
        with open(args.output, "w", encoding="utf-8") as handle:
            handle.write(text)
    else:
        print(text)
    return 0


def cmd_seed_table(args) -> int:
    from mbh._harness.jobs.seedtable import format_rows, seed_rows

    rows = seed_rows(repeats=args.repeats, bounds=_bounds(args.bounds))
    if args.json:
        _print_json(rows)
    else:
        print(format_rows(rows))
    return 0


def _results_root(args):
    from pathlib import Path

    return Path(args.root) if args.root else None


def _open_run(run_id: str, root):
    from mbh._harness.store.runs import RunStore

    try:
        return RunStore.open(run_id, root)
    except (FileNotFoundError, ValueError) as error:  # no such run, or an unreadable manifest
        raise UserError(str(error)) from None


def _records(frame) -> list[dict]:
    """Rows of ``frame`` as dicts of plain values (a missing value of a nullable column: None)."""
    import pandas as pd

    return [{key: None if value is pd.NA else value for key, value in row.items()}
            for row in frame.to_dict("records")]


def _cell(value) -> str:
    return f"{value:.3g}" if isinstance(value, float) else str(value)


def _status_counts(frame) -> str:
    counts = frame["status"].value_counts() if len(frame) else {}
    return ", ".join(f"{status} {count}" for status, count in sorted(dict(counts).items()))


def _interrupted_exit(stop: KeyboardInterrupt) -> int:
    """The shell's exit status of a run stopped by a signal: 128 + its number (130 for Ctrl-C,
    143 for SIGTERM, 129 for SIGHUP)."""
    return 128 + int(getattr(stop, "signum", signal.SIGINT))


def cmd_run(args) -> int:
    """Run a campaign into the result store (see :mod:`mbh._harness.run.campaign`)."""
    from mbh._harness.run.spec import CampaignError, load_campaign
    from mbh._harness.run.campaign import CampaignInterrupted, RunnerError, run_campaign
    from mbh._harness.store.problems import StoreError

    try:
        campaign = load_campaign(args.campaign)
    except CampaignError as error:
        raise UserError(str(error)) from None
    try:
        store = run_campaign(campaign, workers=args.workers, scheduler=args.scheduler,
                             resume=args.resume, reuse=args.reuse, root=_results_root(args),
                             quiet=args.quiet, warm_workers=not args.cold_workers)
    except (RunnerError, StoreError) as error:  # StoreError: a read-only or full results root
        raise UserError(str(error)) from None
    except CampaignInterrupted as stop:  # before KeyboardInterrupt: it is one
        cases = stop.store.cases()
        print(f"mbh: interrupted; run {stop.store.run_id} keeps {len(cases)} finished cases "
              f"({_status_counts(cases)}); complete it with: mbh run {args.campaign} --resume "
              f"{stop.store.run_id}", file=sys.stderr)
        return _interrupted_exit(stop)
    except KeyboardInterrupt as stop:
        print("mbh: interrupted before the run started; nothing was stored", file=sys.stderr)
        return _interrupted_exit(stop)
    cases = store.cases()
    print(f"run {store.run_id}: {store.manifest['status']}, {len(cases)} cases "
          f"({_status_counts(cases)})")
    print(f"path {store.path}")
    return 0


BENCH_PARTS = ("front", "overhead", "fallback", "scaling", "references")


def cmd_bench(args) -> int:
    """The speed figures of :mod:`mbh._harness.jobs.bench`, measured in this run, printed as tables."""
    from mbh._harness.jobs import bench

    parts = args.parts.split(",")
    unknown = sorted(set(parts) - set(BENCH_PARTS))
    if unknown:
        raise UserError(f"--parts: unknown part(s) {', '.join(unknown)} (valid: "
                        f"{', '.join(BENCH_PARTS)})")
    if "front" in parts:
        _bench_front(args)
    if "overhead" in parts:
        print("\nadapter time per step / bare loop time per step (dt 1e-3 s, 4 s, best of 5)")
        rows = bench.overhead_rows()
        _print_table([{**r, **{k: format_number(r[k])
                               for k in ("adapter_us_per_step", "bare_us_per_step", "ratio",
                                         "read_back_us_per_sample")}}
                      for r in rows], ["adapter", "scenario", "method", "adapter_us_per_step",
                                       "bare_us_per_step", "ratio", "read_back_us_per_sample",
                                       "note"])
    if "fallback" in parts:
        print(f"\nright-hand sides the generated loop handed back to the kernels "
              f"({bench.FALLBACK_METHOD}, dt 1e-4 s, up to 1 s)")
        _print_table([{**r, "fraction": format_number(r["fraction"])}
                      for r in bench.fallback_rows()],
                     ["scenario", "status", "kernel_calls", "rhs_evals", "fraction", "note"])
    if "scaling" in parts:
        members = tuple(n for n in bench.SCALING_N if n <= args.scaling_max)
        print("\ncost per simulated second on n_fourbar@N (best, dt 1e-3 s, 0.5 s), s/s")
        rows, exponents = bench.scaling_rows(members=members)
        table = {}
        for row in rows:
            table.setdefault(row["adapter"], {"adapter": row["adapter"]})[f"N={row['N']}"] = \
                format_number(row["s_per_sim_s"]) if row["status"] == "ok" else row["status"]
        for name, row in table.items():
            row["exponent (N>=4)"] = format_number(exponents[name])
        _print_table(list(table.values()), ["adapter", *(f"N={n}" for n in members),
                                            "exponent (N>=4)"])
    if "references" in parts:
        print("\nreference build time per route, s (stored: when built; now: this run)")
        rows = bench.reference_rows()
        _print_table([{**r, "stored_s": format_number(r["stored_s"]),
                       "now_s": format_number(r["now_s"])}
                      for r in rows], ["scenario", "route", "stored_s", "now_s"])
    return 0


def _bench_front(args) -> None:
    from mbh._harness.run.spec import load_campaign
    from mbh._harness.report.summary import front_ratio_table
    from mbh._harness.run.campaign import run_campaign

    store = run_campaign(load_campaign("bench"), workers=args.workers, root=_results_root(args),
                         quiet=True)
    cases = store.cases()
    print(f"fronts from run {store.run_id} ({len(cases)} cases, {_status_counts(cases)})")
    for name in sorted(cases["scenario"].unique()):
        table = front_ratio_table(cases, name)
        print(f"\n{table.caption}")
        rows = [dict(zip(table.columns, (format_number(v) if isinstance(v, float) else v
                                         for v in row))) for row in table.rows]
        _print_table(rows, list(table.columns))


def cmd_runs(args) -> int:
    from mbh._harness.store.manifest import list_runs

    try:
        manifests = list_runs(_results_root(args))
    except ValueError as error:  # an unreadable manifest
        raise UserError(str(error)) from None
    rows = [{"run_id": m["run_id"], "campaign": m["campaign"], "status": m["status"],
             "started": m["started"], "ended": m["ended"], "n_cases": m["n_cases"],
             "calibration_s": m.get("calibration_s"), "git_commit": (m.get("git") or {}).get("commit"),
             "git_dirty": (m.get("git") or {}).get("dirty")} for m in manifests]
    if args.json:
        _print_json(rows)
    elif rows:
        _print_table(rows, ["run_id", "campaign", "status", "started", "ended", "n_cases"])
    else:
        print("no runs")
    _warn_problems(problem for m in manifests for problem in m.get("problems", []))
    return 0


def _warn_problems(problems) -> None:
    """Each damaged stored file on stderr (docs/formats/store.md, "Damaged files")."""
    for problem in problems:
        print(f"mbh: warning: {problem}", file=sys.stderr)


#: Columns of ``mbh show`` without --json (the JSON form has them all).
SHOW_COLUMNS = ["case_id", "status", "failure_time", "main_output_error", "wall_time_s", "reason"]


def cmd_show(args) -> int:
    store = _open_run(args.run, _results_root(args))
    cases = store.cases()
    if args.where:
        try:
            cases = cases.query(args.where)
        except Exception as error:  # noqa: BLE001 — any failure of the user's expression
            raise UserError(f"--where {args.where!r}: {type(error).__name__}: {error}; give a "
                            f"pandas DataFrame.query expression over the columns "
                            f"{', '.join(store.cases().columns)}") from None
    _warn_problems(store.problems)
    if args.json:
        _print_json(_records(cases))
        return 0
    rows = [{c: _cell(row.get(c))[:60] for c in SHOW_COLUMNS} for row in _records(cases)]
    if rows:
        _print_table(rows, SHOW_COLUMNS)
    print(f"{len(rows)} cases of run {store.run_id} ({store.manifest['status']})")
    return 0


def cmd_compare(args) -> int:
    from mbh._harness.store.compare import comparable_calibrations, compare_runs

    root = _results_root(args)
    a, b = _open_run(args.run_a, root), _open_run(args.run_b, root)
    changes = compare_runs(a.cases(), b.cases(), *comparable_calibrations(a, b))
    if args.json:
        _print_json(_records(changes))
        return 0
    columns = ["case_id", "change", "status_a", "status_b", "error_ratio", "time_ratio"]
    rows = [{c: _cell(row[c]) for c in columns} for row in _records(changes)]
    if rows:
        _print_table(rows, columns)
    counts = changes["change"].value_counts()
    print(f"{len(rows)} cases in both runs: "
          + ", ".join(f"{change} {count}" for change, count in counts.items()))
    return 0


def cmd_report(args) -> int:
    """Build a stored run's report (HTML and/or PDF, see :mod:`mbh._harness.report.build`); print the
    paths written, the HTML last."""
    from mbh._harness.report.build import ReportError, build_report, parse_formats

    try:
        written = build_report(args.run, against=args.against, formats=parse_formats(args.format),
                               out=args.out, root=_results_root(args))
    except ReportError as error:
        raise UserError(str(error)) from None
    for path in sorted(written.values(), key=lambda p: p.suffix == ".html"):
        print(path)
    return 0


def cmd_history(args) -> int:
    """Build a campaign's history page from its stored runs (see
    :mod:`mbh._harness.report.history_page`); print its path, or with --json the runs and changes."""
    from mbh._harness.report.history import HistoryError, find_changes, load_history
    from mbh._harness.report.history_page import build_history

    try:
        history = load_history(args.campaign, _results_root(args))
    except HistoryError as error:
        raise UserError(str(error)) from None
    changes = find_changes(history)
    page = build_history(history.campaign, _results_root(args), args.out, history=history,
                         changes=changes)
    if args.json:
        _print_json({"campaign": history.campaign, "page": str(page),
                     "runs": _records(history.runs.drop(columns="packages")),
                     "changes": _records(changes)})
        return 0
    print(f"{len(history.runs)} runs of {history.campaign}: "
          + (", ".join(f"{kind} {count}" for kind, count in
                       changes["kind"].value_counts().sort_index().items()) or "no change"))
    print(page)
    return 0


def cmd_nightly(args) -> int:
    """Run a campaign, search its history and compare it with its previous run, report, and gate
    on regressions (see :mod:`mbh._harness.jobs.nightly`); prints the Markdown summary; exit 1 on a
    regression."""
    from mbh._harness.run.spec import CampaignError
    from mbh._harness.jobs.nightly import nightly
    from mbh._harness.run.campaign import CampaignInterrupted, RunnerError

    try:
        outcome = nightly(args.campaign, root=_results_root(args), workers=args.workers,
                          gate=args.gate, error_factor=args.error_factor,
                          time_factor=args.time_factor,
                          summary_path=args.summary,
                          formats=() if args.no_report else ("html", "pdf"), quiet=args.quiet)
    except (CampaignError, RunnerError, ValueError) as error:
        raise UserError(str(error)) from None
    except CampaignInterrupted as stop:
        print(f"mbh: interrupted; run {stop.store.run_id} is stored incomplete, nothing was "
              f"compared", file=sys.stderr)
        return _interrupted_exit(stop)
    print(outcome.summary, end="")
    print(f"summary {outcome.summary_path}")
    return outcome.exit_code


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="mbh", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("scenarios", help="list the shipped scenarios")
    p.add_argument("--json", action="store_true", help=JSON_HELP)
    p.set_defaults(func=cmd_scenarios)

    p = sub.add_parser("check", help="kinematic analysis: assembly, rank, mobility, redundancy")
    p.add_argument("name", nargs="?")
    p.add_argument("--all", action="store_true")
    p.add_argument("--quiet", action="store_true", help=QUIET_HELP)
    p.add_argument("--json", action="store_true", help=JSON_HELP)
    p.set_defaults(func=cmd_check)

    p = sub.add_parser("adapters", help="list the adapters, built-in and installed (entry "
                       "points mbh.adapters), with their origin and versions")
    p.add_argument("--json", action="store_true", help=JSON_HELP)
    p.set_defaults(func=cmd_adapters)

    p = sub.add_parser("methods", help="list an adapter's methods with their parameters")
    p.add_argument("--adapter", default="inhouse")
    p.add_argument("--json", action="store_true", help=JSON_HELP)
    p.set_defaults(func=cmd_methods)

    p = sub.add_parser("simulate", help="run one case and measure it against the reference")
    p.add_argument("name")
    p.add_argument("--adapter", default="inhouse")
    p.add_argument("--method", default="default")
    p.add_argument("--dt", type=float, required=True, help="step size, s")
    p.add_argument("--t-end", type=float, default=None, help="end time, s (default: duration)")
    p.add_argument("--no-reference", action="store_true", help="skip the reference comparison")
    p.add_argument("--bounds", default=None, help=BOUNDS_HELP)
    p.add_argument("--quiet", action="store_true", help=QUIET_HELP)
    p.add_argument("--json", action="store_true", help=JSON_HELP)
    p.set_defaults(func=cmd_simulate)

    p = sub.add_parser("seed-table", help="the seed's comparison table (Rouvinen 2003, ch. 7 setup)")
    p.add_argument("--repeats", type=int, default=3, help="runs per case for the mean wall time")
    p.add_argument("--bounds", default=None, help=BOUNDS_HELP)
    p.add_argument("--json", action="store_true", help=JSON_HELP)
    p.set_defaults(func=cmd_seed_table)

    p = sub.add_parser("reference", help="build a scene's verified reference ahead of its first "
                       "case (into the user cache; a progress bar on a terminal)")
    p.add_argument("name", help="scenario name or file")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--json", action="store_true", help=JSON_HELP)
    p.set_defaults(func=cmd_reference)

    p = sub.add_parser("warm-up", help="compile the in-house kernels and loops ahead of the "
                       "first runs, on every core (minutes once per machine and version)")
    p.add_argument("--jobs", type=_positive_int, default=None,
                   help="processes (default: the cores)")
    p.add_argument("--quiet", action="store_true", help=QUIET_HELP)
    p.add_argument("--json", action="store_true", help=JSON_HELP)
    p.set_defaults(func=cmd_warm_up)

    p = sub.add_parser("export", help="write the engine model an adapter generates (MJCF)")
    p.add_argument("name")
    p.add_argument("--adapter", default="mujoco")
    p.add_argument("--output", "-o", default=None)
    p.set_defaults(func=cmd_export)

    root_help = ("results root (default: $MBH_RESULTS_DIR, else results/ in a checkout, else the "
                 "user data folder)")
    p = sub.add_parser("run", help="run a campaign into the result store")
    p.add_argument("campaign", help="campaign name (campaigns/NAME.toml) or file")
    p.add_argument("--workers", type=_positive_int, default=None,
                   help="local worker processes (default and maximum: the cores)")
    p.add_argument("--scheduler", default=None, help="Dask scheduler address, tcp://HOST:PORT")
    p.add_argument("--resume", default=None, metavar="RUN", help="complete interrupted run RUN")
    p.add_argument("--reuse", action="store_true", help="copy identical cases from the cache")
    p.add_argument("--cold-workers", action="store_true",
                   help="start every case in a fresh interpreter instead of forking it from the "
                        "warm template (slower; for comparison)")
    p.add_argument("--quiet", action="store_true", help="no progress bar, no notes")
    p.add_argument("--root", default=None, help=root_help)
    p.set_defaults(func=cmd_run)

    p = sub.add_parser("bench", help="speed: in-house front vs the best engine, adapter "
                                     "overheads, generated-loop fallbacks, scaling on "
                                     "n_fourbar@N, reference build times")
    p.add_argument("--parts", default=",".join(BENCH_PARTS),
                   help=f"comma-separated subset of {', '.join(BENCH_PARTS)} (default: all)")
    p.add_argument("--workers", type=_positive_int, default=None,
                   help="worker processes of the front campaign (default: the cores)")
    p.add_argument("--scaling-max", type=_positive_int, default=64,
                   help="largest N of the scaling table (default 64)")
    p.add_argument("--root", default=None, help=root_help)
    p.set_defaults(func=cmd_bench)

    p = sub.add_parser("runs", help="list the stored runs, oldest first")
    p.add_argument("--json", action="store_true", help=JSON_HELP)
    p.add_argument("--root", default=None, help=root_help)
    p.set_defaults(func=cmd_runs)

    p = sub.add_parser("show", help="a stored run's cases, one row each")
    p.add_argument("run")
    p.add_argument("--where", default=None, help="pandas DataFrame.query expression, e.g. "
                   "\"status != 'ok' and adapter == 'mujoco'\"")
    p.add_argument("--json", action="store_true", help=JSON_HELP)
    p.add_argument("--root", default=None, help=root_help)
    p.set_defaults(func=cmd_show)

    p = sub.add_parser("compare", help="what changed between two runs (accuracy, calibrated "
                       "speed, failing/passing)")
    p.add_argument("run_a")
    p.add_argument("run_b")
    p.add_argument("--json", action="store_true", help=JSON_HELP)
    p.add_argument("--root", default=None, help=root_help)
    p.set_defaults(func=cmd_compare)

    p = sub.add_parser("report", help="build a stored run's report (HTML and PDF); never re-runs")
    p.add_argument("run")
    p.add_argument("--against", default=None, metavar="PREV",
                   help="previous run to compare with; 'previous' = the latest earlier run of "
                        "the same campaign (none if there is none)")
    p.add_argument("--format", default="html,pdf", help="html, pdf or html,pdf (default)")
    p.add_argument("--out", default=None, help="output folder (default: reports/RUN/)")
    p.add_argument("--root", default=None, help=root_help)
    p.set_defaults(func=cmd_report)

    p = sub.add_parser("history", help="a campaign's history over its stored runs: steps in "
                       "each case's status, errors and calibrated time, as an HTML page")
    p.add_argument("--campaign", default=None,
                   help="campaign name (default: the campaign of the latest finished run)")
    p.add_argument("--root", default=None, help=root_help)
    p.add_argument("--out", default=None,
                   help="output folder (default: reports/history-CAMPAIGN/)")
    p.add_argument("--json", action="store_true", help=JSON_HELP)
    p.set_defaults(func=cmd_history)

    from mbh._harness.jobs.nightly import (DEFAULT_CAMPAIGN, DEFAULT_GATE, ERROR_FACTOR, GATES,
                                      TIME_FACTOR)

    p = sub.add_parser("nightly", help="run a campaign, gate on the steps of its history (or on "
                       "its previous run), build its report and history page; exit 1 on a "
                       "regression")
    p.add_argument("--campaign", default=DEFAULT_CAMPAIGN,
                   help=f"campaign name or file (default: {DEFAULT_CAMPAIGN})")
    p.add_argument("--root", default=None, help=root_help)
    p.add_argument("--workers", type=_positive_int, default=None,
                   help="local worker processes (default and maximum: the cores)")
    p.add_argument("--gate", choices=GATES, default=DEFAULT_GATE,
                   help="history: fail on a new open step for the worse in the campaign's "
                        "history; previous: fail on a change against the previous run "
                        "(default %(default)s)")
    p.add_argument("--error-factor", type=float, default=ERROR_FACTOR,
                   help="--gate previous: main-output error more than this many times the "
                        "previous run's (default %(default)g)")
    p.add_argument("--time-factor", type=float, default=TIME_FACTOR,
                   help="--gate previous: calibrated wall time more than this many times the "
                        "previous run's (default %(default)g)")
    p.add_argument("--summary", default=None, metavar="PATH",
                   help="Markdown summary file (default: <run folder>/nightly_summary.md)")
    p.add_argument("--no-report", action="store_true", help="skip the HTML/PDF report")
    p.add_argument("--quiet", action="store_true", help="no progress bar, no notes")
    p.set_defaults(func=cmd_nightly)
    return parser


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number of at least 1, got {text!r}")
    return value


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    waits.show_on_stderr(quiet=getattr(args, "quiet", False))
    try:
        with capture.answers_only_on_stdout():
            return args.func(args)
    except UserError as error:
        print(f"mbh: {error}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # output piped into a pager or head that closed early
        sys.stderr.close()
        return 0


if __name__ == "__main__":
    raise SystemExit(main())
