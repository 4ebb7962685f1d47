"""Cases run on the spot: ``mbh simulate`` (one case, judged) and ``mbh seed-table`` (the
seed's comparison)."""

from __future__ import annotations

import sys

from mbh._harness.common.status import CaseStatus
from mbh._harness.commands import exits
from mbh._harness.commands.options import positive_int, positive_number, shared
from mbh._harness.commands.output import print_fields, print_json
from mbh._harness.measure.verdict import DEFAULT_ACCURACY
from mbh._harness.model import scenario


def add_commands(sub) -> None:
    """Add ``simulate`` and ``seed-table`` to the subparsers ``sub``."""
    p = sub.add_parser("simulate", help="run one case and measure it against the reference; "
                       "exit 1 when it is not ok (or, given --accuracy, not accurate)")
    p.add_argument("name")
    p.add_argument("--adapter", default="inhouse")
    p.add_argument("--method", default="default")
    p.add_argument("--dt", type=float, required=True, help="step size, s")
    p.add_argument("--t-end", type=float, default=None, help="end time, s (default: duration)")
    p.add_argument("--no-reference", action="store_true", help="skip the reference comparison")
    p.add_argument("--accuracy", type=positive_number, default=None,
                   help="largest main-output error against the reference (rad or m) of an "
                        f"accurate case; given, a case that is not accurate exits 1 (default "
                        f"{DEFAULT_ACCURACY:g}, a campaign's, for the printed 'accurate' only)")
    shared(p, "bounds", "quiet", "json")
    p.set_defaults(func=simulate)

    p = sub.add_parser("seed-table", help="the seed's comparison table (Rouvinen 2003, ch. 7 "
                       "setup)")
    p.add_argument("--repeats", type=positive_int, default=3,
                   help="runs per case for the mean wall time")
    shared(p, "bounds", "json")
    p.set_defaults(func=seed_table)


def _reference(mech):
    """``mech``'s verified reference, or None (said on stderr) when its build is refused."""
    from mbh._harness.references.build import ReferenceBuildError, reference_trajectory

    try:
        return reference_trajectory(mech)
    except ReferenceBuildError as error:  # the case still runs, judged without a reference
        print(f"mbh: no reference: {error}", file=sys.stderr)
        return None


def simulate(args) -> int:
    """Run one case (:func:`mbh._harness.run.case.run_case`), its arguments checked first by the
    Python API's rules (:func:`mbh._harness.run.single.check_case`: every problem named, exit 2);
    print its metrics and whether it is ``accurate`` (None without a reference).

    Exit status 0 when the case is ``ok`` and, when ``--accuracy`` is given and a reference
    measured it, accurate within it; 1 otherwise.  Without ``--accuracy`` the printed
    ``accurate`` uses a campaign's default and the status alone decides the exit status: a
    first ``mbh simulate`` whose case is ``ok`` exits 0, however coarse its step.
    """
    from mbh._adapters import get_adapter
    from mbh._harness.run.case import run_case
    from mbh._harness.run.single import check_case
    from mbh._harness.run.spec import main_output

    mech = scenario.load(args.name)
    t_end = check_case(mech, args.adapter, args.method, args.dt, args.t_end)
    adapter = get_adapter(args.adapter)
    reference = None if args.no_reference else _reference(mech)
    case = run_case(adapter, mech, args.method, args.dt, t_end, reference, args.bounds)
    error = case.metrics.get("output_errors", {}).get(main_output(mech), float("nan"))
    accuracy = DEFAULT_ACCURACY if args.accuracy is None else args.accuracy
    accurate = None if reference is None else bool(case.status == CaseStatus.OK
                                                   and error <= accuracy)
    result = {"scenario": mech.name, "adapter": adapter.name, "version": adapter.version(),
              "method": args.method, "dt": args.dt, "t_end": t_end, **case.metrics,
              "accurate": accurate}
    if args.json:
        print_json(result)
    else:
        print_fields(result, 28)
    passed = case.status == CaseStatus.OK and (args.accuracy is None or accurate is not False)
    return exits.OK if passed else exits.NOT_PASSED


def seed_table(args) -> int:
    """The seed's comparison (:mod:`mbh._harness.jobs.seedtable`), run the seed's way."""
    from mbh._harness.jobs.seedtable import format_rows, seed_rows

    rows = seed_rows(repeats=args.repeats, bounds=args.bounds)
    if args.json:
        print_json(rows)
    else:
        print(format_rows(rows))
    return exits.OK
