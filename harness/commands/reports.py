"""Pages from stored runs: ``mbh report`` (a run's report) and ``mbh history`` (a campaign's
history page); neither re-runs anything."""

from __future__ import annotations

from mbh._harness.commands import exits
from mbh._harness.commands.options import shared
from mbh._harness.commands.output import print_json, records


def add_commands(sub) -> None:
    """Add ``report`` and ``history`` to the subparsers ``sub``."""
    p = sub.add_parser("report", help="build a stored run's report (HTML and PDF); never re-runs")
    p.add_argument("run")
    p.add_argument("--against", default=None, metavar="PREV",
                   help="previous run to compare with; 'previous' = the latest earlier run of "
                        "the same campaign (none if there is none)")
    p.add_argument("--format", default="html,pdf", help="html, pdf or html,pdf (default)")
    p.add_argument("--out", default=None, help="output folder (default: ROOT/reports/RUN/)")
    shared(p, "root")
    p.set_defaults(func=report)

    p = sub.add_parser("history", help="a campaign's history over its stored runs: steps in "
                       "each case's status, errors and calibrated time, as an HTML page")
    p.add_argument("--campaign", default=None,
                   help="campaign name (default: the campaign of the latest finished run)")
    shared(p, "root")
    p.add_argument("--out", default=None,
                   help="output folder (default: ROOT/reports/history-CAMPAIGN/)")
    shared(p, "json")
    p.set_defaults(func=history)


def report(args) -> int:
    """Build a stored run's report (HTML and/or PDF, see :mod:`mbh._harness.report.build`) and
    print the paths written, the HTML last."""
    from mbh._harness.report.build import build_report, parse_formats

    written = build_report(args.run, against=args.against, formats=parse_formats(args.format),
                           out=args.out, root=args.root)
    for path in sorted(written.values(), key=lambda p: p.suffix == ".html"):
        print(path)
    return exits.OK


def history(args) -> int:
    """Build a campaign's history page from its stored runs (see
    :mod:`mbh._harness.report.history_page`); print a count of its changes and its path, or with
    --json the runs and changes."""
    from mbh._harness.report.history import find_changes, load_history
    from mbh._harness.report.history_page import build_history

    found = load_history(args.campaign, args.root)
    changes = find_changes(found)
    page = build_history(found.campaign, args.root, args.out, history=found, changes=changes)
    if args.json:
        print_json({"campaign": found.campaign, "page": str(page),
                    "runs": records(found.runs.drop(columns="packages")),
                    "changes": records(changes)})
        return exits.OK
    print(f"{len(found.runs)} runs of {found.campaign}: "
          + (", ".join(f"{kind} {count}" for kind, count in
                       changes["kind"].value_counts().sort_index().items()) or "no change"))
    print(page)
    return exits.OK
