"""The result store: ``mbh runs``, ``mbh show``, ``mbh compare``."""

from __future__ import annotations

from mbh._harness.commands import exits
from mbh._harness.commands.options import shared
from mbh._harness.commands.output import (cell, print_json, print_table, records,
                                          warn_problems)

#: Columns of ``mbh show`` without --json (the JSON form has them all).
SHOW_COLUMNS = ["case_id", "status", "failure_time", "main_output_error", "wall_time_s", "reason"]
#: Columns of ``mbh compare`` without --json.
COMPARE_COLUMNS = ["case_id", "change", "status_a", "status_b", "error_ratio", "time_ratio"]


def add_commands(sub) -> None:
    """Add ``runs``, ``show`` and ``compare`` to the subparsers ``sub``."""
    p = sub.add_parser("runs", help="list the stored runs, oldest first")
    shared(p, "json", "root")
    p.set_defaults(func=list_runs)

    p = sub.add_parser("show", help="a stored run's cases, one row each")
    p.add_argument("run")
    p.add_argument("--where", default=None, help="pandas DataFrame.query expression, e.g. "
                   "\"status != 'ok' and adapter == 'mujoco'\"")
    shared(p, "json", "root")
    p.set_defaults(func=show)

    p = sub.add_parser("compare", help="what changed between two runs (accuracy, calibrated "
                       "speed, failing/passing)")
    p.add_argument("run_a")
    p.add_argument("run_b")
    shared(p, "json", "root")
    p.set_defaults(func=compare)


def open_run(run_id: str, root):
    """The stored run ``run_id`` under ``root``; a run that does not exist is a
    :class:`~mbh._harness.commands.exits.UsageError` listing the runs there are."""
    from mbh._harness.store.runs import RunStore

    try:
        return RunStore.open(run_id, root)
    except FileNotFoundError as error:
        raise exits.UsageError(str(error)) from None


def list_runs(args) -> int:
    """The stored runs' manifests, oldest first; damaged files named on stderr."""
    from mbh._harness.store import runs

    manifests = runs.list_runs(args.root)
    rows = [{"run_id": m["run_id"], "campaign": m["campaign"], "status": m["status"],
             "started": m["started"], "ended": m["ended"], "n_cases": m["n_cases"],
             "calibration_s": m.get("calibration_s"),
             "git_commit": (m.get("git") or {}).get("commit"),
             "git_dirty": (m.get("git") or {}).get("dirty")} for m in manifests]
    if args.json:
        print_json(rows)
    elif rows:
        print_table(rows, ["run_id", "campaign", "status", "started", "ended", "n_cases"])
    else:
        print("no runs")
    warn_problems(problem for m in manifests for problem in m.get("problems", []))
    return exits.OK


def show(args) -> int:
    """A stored run's cases (those ``--where`` keeps), one row each."""
    store = open_run(args.run, args.root)
    cases = store.cases()
    if args.where:
        try:
            cases = cases.query(args.where)
        except Exception as error:  # noqa: BLE001 — any failure of the user's expression
            raise exits.UsageError(
                f"--where {args.where!r}: {type(error).__name__}: {error}; give a pandas "
                f"DataFrame.query expression over the columns "
                f"{', '.join(store.cases().columns)}") from None
    warn_problems(store.problems)
    if args.json:
        print_json(records(cases))
        return exits.OK
    rows = [{c: cell(row.get(c))[:60] for c in SHOW_COLUMNS} for row in records(cases)]
    if rows:
        print_table(rows, SHOW_COLUMNS)
    print(f"{len(rows)} cases of run {store.run_id} ({store.manifest['status']})")
    return exits.OK


def compare(args) -> int:
    """What changed from run A to run B, case by case
    (:func:`mbh._harness.store.compare.compare_runs`)."""
    from mbh._harness.store.compare import comparable_calibrations, compare_runs

    a, b = open_run(args.run_a, args.root), open_run(args.run_b, args.root)
    changes = compare_runs(a.cases(), b.cases(), *comparable_calibrations(a, b))
    if args.json:
        print_json(records(changes))
        return exits.OK
    rows = [{c: cell(row[c]) for c in COMPARE_COLUMNS} for row in records(changes)]
    if rows:
        print_table(rows, COMPARE_COLUMNS)
    counts = changes["change"].value_counts()
    print(f"{len(rows)} cases in both runs: "
          + ", ".join(f"{change} {count}" for change, count in counts.items()))
    return exits.OK
