"""Campaigns: ``mbh run`` (into the result store) and ``mbh nightly`` (run, compare, report,
gate)."""

from __future__ import annotations

import sys

from mbh._harness.commands import exits
from mbh._harness.commands.options import above_one, shared
from mbh._harness.commands.output import status_counts
from mbh._harness.jobs.nightly import (DEFAULT_CAMPAIGN, DEFAULT_GATE, ERROR_FACTOR, GATES,
                                       TIME_FACTOR)

RUN_QUIET_HELP = "no progress bar, no notes"


def add_commands(sub) -> None:
    """Add ``run`` and ``nightly`` to the subparsers ``sub``."""
    p = sub.add_parser("run", help="run a campaign into the result store (exit 0 once it is "
                       "stored, whatever its cases' statuses)")
    p.add_argument("campaign", help="campaign name (campaigns/NAME.toml) or file")
    shared(p, "workers")
    p.add_argument("--scheduler", default=None, help="Dask scheduler address, tcp://HOST:PORT")
    p.add_argument("--resume", default=None, metavar="RUN", help="complete interrupted run RUN")
    p.add_argument("--reuse", action="store_true", help="copy identical cases from the cache")
    p.add_argument("--cold-workers", action="store_true",
                   help="start every case in a fresh interpreter instead of forking it from the "
                        "warm template (slower; for comparison)")
    shared(p, "quiet", "root", quiet=RUN_QUIET_HELP)
    p.set_defaults(func=run)

    p = sub.add_parser("nightly", help="run a campaign, gate on the steps of its history (or on "
                       "its previous run), build its report and history page; exit 1 on a "
                       "regression, 3 when a report could not be built")
    p.add_argument("--campaign", default=DEFAULT_CAMPAIGN,
                   help=f"campaign name or file (default: {DEFAULT_CAMPAIGN})")
    shared(p, "root", "workers")
    p.add_argument("--gate", choices=GATES, default=DEFAULT_GATE,
                   help="history: fail on a new open step for the worse in the campaign's "
                        "history; previous: fail on a change against the previous run "
                        "(default %(default)s)")
    p.add_argument("--error-factor", type=above_one, default=ERROR_FACTOR,
                   help="--gate previous: main-output error more than this many times the "
                        "previous run's (default %(default)g)")
    p.add_argument("--time-factor", type=above_one, default=TIME_FACTOR,
                   help="--gate previous: calibrated wall time more than this many times the "
                        "previous run's (default %(default)g)")
    p.add_argument("--summary", default=None, metavar="PATH",
                   help="Markdown summary file (default: <run folder>/nightly_summary.md)")
    p.add_argument("--no-report", action="store_true", help="skip the HTML/PDF report")
    shared(p, "quiet", quiet=RUN_QUIET_HELP)
    p.set_defaults(func=nightly)


def run(args) -> int:
    """Run a campaign into the result store (see :mod:`mbh._harness.run.campaign`) and say its
    status, case counts and folder.  Stopped by a signal: what was kept and how to complete it,
    exit 128 + the signal's number."""
    from mbh._harness.run.campaign import CampaignInterrupted, run_campaign
    from mbh._harness.run.spec import load_campaign

    campaign = load_campaign(args.campaign)
    try:
        store = run_campaign(campaign, workers=args.workers, scheduler=args.scheduler,
                             resume=args.resume, reuse=args.reuse, root=args.root,
                             quiet=args.quiet, warm_workers=not args.cold_workers)
    except CampaignInterrupted as stop:  # before KeyboardInterrupt: it is one
        cases = stop.store.cases()
        print(f"mbh: interrupted; run {stop.store.run_id} keeps {len(cases)} finished cases "
              f"({status_counts(cases)}); complete it with: mbh run {args.campaign} --resume "
              f"{stop.store.run_id}", file=sys.stderr)
        return exits.interrupted(stop)
    except KeyboardInterrupt as stop:
        print("mbh: interrupted before the run started; nothing was stored", file=sys.stderr)
        return exits.interrupted(stop)
    cases = store.cases()
    print(f"run {store.run_id}: {store.manifest['status']}, {len(cases)} cases "
          f"({status_counts(cases)})")
    print(f"path {store.path}")
    return exits.OK


def nightly(args) -> int:
    """Run a campaign, search its history and compare it with its previous run, report, and gate
    on regressions (see :mod:`mbh._harness.jobs.nightly`); print the Markdown summary.  Exit
    status: :attr:`mbh._harness.jobs.nightly.NightlyOutcome.exit_code` (0, 1 a regression, 3 a
    report not built); stopped by a signal, 128 + its number."""
    from mbh._harness.jobs.nightly import nightly as run_nightly
    from mbh._harness.run.campaign import CampaignInterrupted

    try:
        outcome = run_nightly(args.campaign, root=args.root, workers=args.workers,
                              gate=args.gate, error_factor=args.error_factor,
                              time_factor=args.time_factor, summary_path=args.summary,
                              formats=() if args.no_report else ("html", "pdf"),
                              quiet=args.quiet)
    except CampaignInterrupted as stop:
        print(f"mbh: interrupted; run {stop.store.run_id} is stored incomplete, nothing was "
              f"compared", file=sys.stderr)
        return exits.interrupted(stop)
    print(outcome.summary, end="")
    print(f"summary {outcome.summary_path}")
    return outcome.exit_code
