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
    return parser


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except UserError as error:
        print(f"mbh: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
