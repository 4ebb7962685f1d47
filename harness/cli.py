"""The ``mbh`` command line.

Every user error (bad scenario file, unknown method, a mechanism that cannot be assembled) prints
one clear message per problem on stderr and exits with status 2; it never shows a traceback.
"""

from __future__ import annotations

import argparse
import json
import sys

from harness import scenario
from harness.scenario import ScenarioError


class UserError(Exception):
    """A problem with the user's input; printed without a traceback."""


def _load(name: str):
    try:
        return scenario.load(name)
    except ScenarioError as error:
        raise UserError(str(error)) from None


def _print_table(rows: list[dict], columns: list[str]) -> None:
    widths = {c: max(len(c), *(len(str(r.get(c, ""))) for r in rows)) for c in columns}
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
        print(json.dumps(rows, indent=2))
    else:
        _print_table(rows, ["name", "kind", "bodies", "joints", "tags"])
    return 0


def _names(args) -> list[str]:
    if args.all == bool(args.name):
        raise UserError("give a scenario NAME or --all")
    return scenario.scenario_names() if args.all else [args.name]


def cmd_check(args) -> int:
    from adapters.inhouse.kinematics import AssemblyError, check

    results, failed = [], False
    for name in _names(args):
        try:
            results.append(check(_load(name)))
        except (AssemblyError, UserError) as error:
            failed = True
            results.append({"scenario": name, "error": str(error)})
    if args.json:
        print(json.dumps(results, indent=2))
    else:
        for result in results:
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
        print(json.dumps(rows, indent=2))
    else:
        print(f"{adapter.version()}: {len(rows)} methods")
        _print_table(rows, ["method", "parameters", "description"])
    return 0


def _adapter(name: str):
    from adapters import get_adapter

    try:
        return get_adapter(name)
    except ValueError as error:
        raise UserError(str(error)) from None


def cmd_simulate(args) -> int:
    from harness.metrics import case_metrics
    from harness.reference import ReferenceError, reference_trajectory
    from harness.sampling import sample_times

    mech = _load(args.name)
    adapter = _adapter(args.adapter)
    t_end = mech.duration if args.t_end is None else args.t_end
    if not 0 < t_end <= mech.duration:
        raise UserError(f"--t-end must be in (0, {mech.duration:g}] s, got {t_end:g}")
    if args.dt <= 0:
        raise UserError(f"--dt must be > 0, got {args.dt:g}")
    try:
        adapter.method_spec(args.method)
    except ValueError as error:
        raise UserError(str(error)) from None
    times = sample_times(args.dt, t_end)
    trajectory = _run_case(adapter, mech, args.method, args.dt, t_end, times)
    reference = None
    if not args.no_reference:
        try:
            reference = reference_trajectory(mech)
        except ReferenceError as error:
            print(f"mbh: no reference: {error}", file=sys.stderr)
    result = {"scenario": mech.name, "adapter": adapter.name, "version": adapter.version(),
              "method": args.method, "dt": args.dt, "t_end": t_end,
              **case_metrics(mech, trajectory, reference)}
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        for key, value in result.items():
            print(f"{key:28s} {value}")
    return 0


def _run_case(adapter, mech, method, dt, t_end, times):
    """Build and simulate one case; an engine that cannot build it gives an unsupported row."""
    from adapters.base import UnsupportedCase
    from harness.trajectory import Trajectory

    try:
        model = adapter.build(mech)
    except UnsupportedCase as error:
        return Trajectory.empty(len(mech.bodies), status="unsupported", reason=str(error))
    return adapter.simulate(model, method, dt, t_end, times)


def cmd_export(args) -> int:
    mech = _load(args.name)
    if args.adapter != "mujoco":
        raise UserError(f"export is available for the mujoco adapter, not {args.adapter!r}")
    from adapters.base import UnsupportedCase
    from adapters.mujoco_adapter import export_mjcf

    try:
        text = export_mjcf(mech)
    except UnsupportedCase as error:
        raise UserError(f"{mech.name}: {error}") from None
    if args.output:
        with open(args.output, "w", encoding="utf-8") as handle:
            handle.write(text)
    else:
        print(text)
    return 0


def cmd_seed_table(args) -> int:
    from harness.seedtable import format_rows, seed_rows

    rows = seed_rows(repeats=args.repeats)
    print(json.dumps(rows, indent=2) if args.json else format_rows(rows))
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="mbh", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("scenarios", help="list the shipped scenarios")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_scenarios)

    p = sub.add_parser("check", help="kinematic analysis: assembly, rank, mobility, redundancy")
    p.add_argument("name", nargs="?")
    p.add_argument("--all", action="store_true")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_check)

    p = sub.add_parser("methods", help="list an adapter's methods with their parameters")
    p.add_argument("--adapter", default="inhouse")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_methods)

    p = sub.add_parser("simulate", help="run one case and measure it against the reference")
    p.add_argument("name")
    p.add_argument("--adapter", default="inhouse")
    p.add_argument("--method", default="default")
    p.add_argument("--dt", type=float, required=True, help="step size, s")
    p.add_argument("--t-end", type=float, default=None, help="end time, s (default: duration)")
    p.add_argument("--no-reference", action="store_true", help="skip the reference comparison")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_simulate)

    p = sub.add_parser("seed-table", help="the seed's comparison table (Rouvinen 2003, ch. 7 setup)")
    p.add_argument("--repeats", type=int, default=3, help="runs per case for the mean wall time")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_seed_table)

    p = sub.add_parser("export", help="write the engine model an adapter generates (MJCF)")
    p.add_argument("name")
    p.add_argument("--adapter", default="mujoco")
    p.add_argument("--output", "-o", default=None)
    p.set_defaults(func=cmd_export)
    return parser


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except UserError as error:
        print(f"mbh: {error}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # output piped into a pager or head that closed early
        sys.stderr.close()
        return 0


if __name__ == "__main__":
    raise SystemExit(main())
