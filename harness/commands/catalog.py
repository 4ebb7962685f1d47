"""What there is to run: ``mbh scenarios``, ``mbh adapters``, ``mbh methods``."""

from __future__ import annotations

import sys

from mbh._harness.commands import exits
from mbh._harness.commands.options import shared
from mbh._harness.commands.output import print_json, print_table
from mbh._harness.model import scenario


def add_commands(sub) -> None:
    """Add ``scenarios``, ``adapters`` and ``methods`` to the subparsers ``sub``."""
    p = sub.add_parser("scenarios", help="list the shipped scenarios")
    shared(p, "json")
    p.set_defaults(func=list_scenarios)

    p = sub.add_parser("adapters", help="list the adapters, built-in and installed (entry "
                       "points mbh.adapters), with their origin and versions; exit 1 when one "
                       "cannot be used")
    shared(p, "json")
    p.set_defaults(func=list_adapters)

    p = sub.add_parser("methods", help="list an adapter's methods with their parameters")
    p.add_argument("--adapter", default="inhouse")
    shared(p, "json")
    p.set_defaults(func=list_methods)


def list_scenarios(args) -> int:
    """The shipped scenarios: kind, bodies, joints, tags (a scenario file with mistakes: the
    loader's error, exit 2)."""
    rows = []
    for name in scenario.scenario_names():
        mech = scenario.load(name)
        rows.append({"name": name, "kind": mech.kind, "bodies": len(mech.bodies),
                     "joints": ", ".join(f"{j.name}:{j.type}" for j in mech.joints),
                     "tags": ", ".join(mech.tags)})
    if args.json:
        print_json(rows)
    else:
        print_table(rows, ["name", "kind", "bodies", "joints", "tags"])
        if not rows:
            print(f"mbh: no scenario files in {scenario.SCENARIO_DIR}", file=sys.stderr)
    return exits.OK


def list_adapters(args) -> int:
    """The registered adapters (built-in and from the ``mbh.adapters`` entry points): origin,
    package version, engine version and method count; a row's ``problem`` says why an adapter
    cannot be used (and the exit status is 1)."""
    from mbh._adapters import inventory

    rows = inventory()
    if args.json:
        print_json(rows)
    else:
        print_table([{key: "" if value is None else value for key, value in row.items()}
                     for row in rows], ["name", "origin", "package_version", "version", "methods",
                                        "problem"])
    return exits.NOT_PASSED if any(row["problem"] for row in rows) else exits.OK


def list_methods(args) -> int:
    """Every method of ``--adapter`` with its parameters and description."""
    from mbh._adapters import get_adapter

    adapter = get_adapter(args.adapter)
    rows = [{"method": spec.name, "parameters": ", ".join(f"{k}={v}" for k, v in
                                                          spec.params.items()),
             "description": spec.description} for spec in adapter.methods()]
    if args.json:
        print_json(rows)
    else:
        print(f"{adapter.version()}: {len(rows)} methods")
        print_table(rows, ["method", "parameters", "description"])
    return exits.OK
