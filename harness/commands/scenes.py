"""One scene at a time: ``mbh check`` (kinematic analysis), ``mbh reference`` (its verified
reference), ``mbh export`` (the engine model an adapter generates)."""

from __future__ import annotations

import sys

from mbh._harness.commands import exits
from mbh._harness.commands.options import shared
from mbh._harness.commands.output import print_fields, print_json
from mbh._harness.model import scenario


def add_commands(sub) -> None:
    """Add ``check``, ``reference`` and ``export`` to the subparsers ``sub``."""
    p = sub.add_parser("check", help="kinematic analysis: assembly, rank, mobility, redundancy; "
                       "exit 1 when the assembly refuses a mechanism")
    p.add_argument("name", nargs="?")
    p.add_argument("--all", action="store_true")
    shared(p, "quiet", "json")
    p.set_defaults(func=check)

    p = sub.add_parser("reference", help="build a scene's verified reference ahead of its first "
                       "case (into the user cache; a progress bar on a terminal); exit 1 when "
                       "the build is refused")
    p.add_argument("name", help="scenario name or file")
    shared(p, "quiet", "json", quiet="no progress bar")
    p.set_defaults(func=reference)

    p = sub.add_parser("export", help="write the engine model an adapter generates (MJCF); exit "
                       "1 when the engine cannot represent the mechanism")
    p.add_argument("name")
    p.add_argument("--adapter", default="mujoco")
    p.add_argument("--output", "-o", default=None)
    p.set_defaults(func=export)


def _names(args) -> list[str]:
    if args.all == bool(args.name):
        raise exits.UsageError("give a scenario NAME or --all")
    return scenario.scenario_names() if args.all else [args.name]


def check(args) -> int:
    """Kinematic analysis by the harness's neutral kinematics (:mod:`mbh._harness.neutral.assembly`,
    :mod:`mbh._harness.neutral.mobility`): assembly residuals, rank, mobility, redundant
    equations, singularity.

    ``n_coordinates`` counts twist coordinates (6 per spatial body, 3 per planar body) and
    ``n_equations`` the joint rows (no driver, no normalisation rows);
    ``redundant_equation_labels`` names the rows the rank-revealing QR leaves over and
    ``dependent_equation_labels`` every row taking part in a dependency (any of which could be
    the one dropped: all 30 on Bricard's mechanism).  A start at a singular configuration
    (condition number above :data:`mbh._harness.neutral.mobility.CONDITION_LIMIT`, or rank lost)
    is refused: its entry has the ``error`` and, with the rank analysis there, a ``warning``;
    the exit status is then 1.
    """
    from mbh._harness.neutral.assembly import AssemblyError, assemble

    mechanisms = [scenario.load(name) for name in _names(args)]  # a bad file: before any output
    results, failed = [], False
    for mech in mechanisms:
        head = {"scenario": mech.name, "kind": mech.kind, "n_bodies": len(mech.bodies)}
        try:
            assembly = assemble(mech)
        except AssemblyError as error:  # a result of the analysis, listed with the others
            failed = True
            report = getattr(error, "report", None)
            results.append({"scenario": mech.name, "error": str(error)}
                           | ({} if report is None else report.fields()))
            continue
        results.append(head | assembly.report.fields() | {
            "assembly_residual": assembly.residual, "assembly_iterations": assembly.iterations,
            "velocity_residual": assembly.velocity_residual})
    if args.json:
        print_json(results)
    else:
        for result in results:
            if "warning" in result:
                print(f"mbh: warning: {result['scenario']}: {result['warning']}", file=sys.stderr)
            print(f"== {result['scenario']}")
            for key, value in result.items():
                if key != "scenario":
                    print(f"  {key:28s} {value}")
    return exits.NOT_PASSED if failed else exits.OK


def reference(args) -> int:
    """Build (or find) a scene's verified reference ahead of its first case and say where it is,
    how well its two routes agree, which route uses no contestant's code and how well it agrees,
    and what it cost (a refused build: exit 1)."""
    from mbh._harness.references.build import load_or_build
    from mbh._harness.store.reference_files import reference_paths

    mech = scenario.load(args.name)
    _, info = load_or_build(mech, show_progress=None if not args.quiet else False)
    data_path, info_path = reference_paths(mech)
    result = {"scenario": mech.name, "content_hash": mech.content_hash,
              "data": str(data_path), "metadata": str(info_path),
              "agreement": info["agreement"]["max"],
              "independent_route": info["independent"]["route"][0],
              "independent_agreement": info["independent"]["difference"]["max"],
              "wall_time_s": sum(info[key]["wall_time_s"]
                                 for key in ("route_a_cost", "route_b_cost"))}
    if args.json:
        print_json(result)
    else:
        print_fields(result, 14)
    return exits.OK


def export(args) -> int:
    """The engine model ``--adapter`` generates for the scene, on stdout or into ``--output``."""
    from mbh._adapters import get_adapter

    mech = scenario.load(args.name)
    text = get_adapter(args.adapter).export(mech)
    if args.output:
        with open(args.output, "w", encoding="utf-8") as handle:
            handle.write(text)
    else:
        print(text)
    return exits.OK
