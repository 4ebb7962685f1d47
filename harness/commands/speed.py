"""Speed: ``mbh warm-up`` (compile ahead of the first runs) and ``mbh bench`` (the speed
figures of :mod:`mbh._harness.jobs.bench`, measured in this run)."""

from __future__ import annotations

import argparse
import time

from mbh._harness.common.status import CaseStatus
from mbh._harness.commands import exits
from mbh._harness.commands.options import positive_int, shared
from mbh._harness.commands.output import print_json, print_table, status_counts
from mbh._harness.common.numbers import format_number

#: The parts of ``mbh bench``, in the order it prints them.
BENCH_PARTS = ("front", "overhead", "fallback", "scaling", "references")


def bench_parts(text: str) -> list[str]:
    """``--parts``: a comma-separated subset of :data:`BENCH_PARTS`."""
    parts = text.split(",")
    unknown = sorted(set(parts) - set(BENCH_PARTS))
    if unknown:
        raise argparse.ArgumentTypeError(f"unknown part(s) {', '.join(unknown)} (valid: "
                                         f"{', '.join(BENCH_PARTS)})")
    return parts


def add_commands(sub) -> None:
    """Add ``warm-up`` and ``bench`` to the subparsers ``sub``."""
    p = sub.add_parser("warm-up", help="compile the in-house kernels and loops ahead of the "
                       "first runs, on every core (minutes once per machine and version)")
    p.add_argument("--jobs", type=positive_int, default=None,
                   help="processes (default: the cores)")
    shared(p, "quiet", "json")
    p.set_defaults(func=warm_up)

    p = sub.add_parser("bench", help="speed: in-house front vs the best engine (and the "
                                     "in-house formulation in both coordinates), adapter "
                                     "overheads, generated-loop fallbacks, scaling on "
                                     "n_fourbar@N, reference build times")
    p.add_argument("--parts", type=bench_parts, default=",".join(BENCH_PARTS),
                   help=f"comma-separated subset of {', '.join(BENCH_PARTS)} (default: all)")
    shared(p, "workers", "root",
           workers="worker processes of the front campaign (default: the cores)")
    p.add_argument("--scaling-max", type=positive_int, default=64,
                   help="largest N of the scaling table (default 64)")
    p.set_defaults(func=bench)


def warm_up(args) -> int:
    """Compile the in-house kernels and loops ahead of the first runs
    (:mod:`mbh._harness.run.warm_up`) and say what each case compiled and how long it took; a
    failed case is listed, not fatal."""
    from mbh._harness.run.executor import usable_cores
    from mbh._harness.run.warm_up import warm_up as compile_cases

    began = time.perf_counter()
    warmed = compile_cases(args.jobs or usable_cores())
    rows = [{"scenario": w.case.scene, "method": w.case.method, "compiles": w.case.what,
             "wall_time_s": w.seconds, "problem": w.problem} for w in warmed]
    if args.json:
        print_json(rows)
        return exits.OK
    problems = [row for row in rows if row["problem"]]
    print(f"warmed up: {len(rows)} cases in {time.perf_counter() - began:.0f} s"
          f"{f', {len(problems)} failed' if problems else ''}")
    for row in problems:
        print(f"  {row['scenario']} {row['method']}: {row['problem']}")
    return exits.OK


def bench(args) -> int:
    """The parts of :mod:`mbh._harness.jobs.bench` asked for, measured now, printed as tables."""
    from mbh._harness.jobs import bench as figures

    if "front" in args.parts:
        _front(args)
    if "overhead" in args.parts:
        print("\nadapter time per step / bare loop time per step (dt 1e-3 s, 4 s, best of 5)")
        numbers = ("adapter_us_per_step", "bare_us_per_step", "ratio", "read_back_us_per_sample")
        print_table([{**r, **{k: format_number(r[k]) for k in numbers}}
                     for r in figures.overhead_rows()],
                    ["adapter", "scenario", "method", *numbers, "note"])
    if "fallback" in args.parts:
        print(f"\nright-hand sides the generated loop handed back to the kernels "
              f"({figures.FALLBACK_METHOD}, dt 1e-4 s, up to 1 s)")
        print_table([{**r, "fraction": format_number(r["fraction"])}
                     for r in figures.fallback_rows()],
                    ["scenario", "status", "kernel_calls", "rhs_evals", "fraction", "note"])
    if "scaling" in args.parts:
        _scaling(figures, tuple(n for n in figures.SCALING_N if n <= args.scaling_max))
    if "references" in args.parts:
        print("\nreference build time per route, s (stored: when built; now: this run)")
        print_table([{**r, "stored_s": format_number(r["stored_s"]),
                      "now_s": format_number(r["now_s"])}
                     for r in figures.reference_rows()], ["scenario", "route", "stored_s",
                                                          "now_s"])
    return exits.OK


def _front(args) -> None:
    """The in-house front against the best engine, per scenario, from a run of ``bench``."""
    from mbh._harness.report.coordinates import coordinates_table
    from mbh._harness.report.summary import front_ratio_table
    from mbh._harness.run.campaign import run_campaign
    from mbh._harness.run.spec import load_campaign

    store = run_campaign(load_campaign("bench"), workers=args.workers, root=args.root,
                         quiet=True)
    cases = store.cases()
    print(f"fronts from run {store.run_id} ({len(cases)} cases, {status_counts(cases)})")
    for name in sorted(cases["scenario"].unique()):
        for table in (front_ratio_table(cases, name), coordinates_table(cases, name)):
            if table is not None:
                _print_report_table(table)


def _print_report_table(table) -> None:
    """A report :class:`~mbh._harness.report.summary.Table` on stdout: caption, then rows."""
    print(f"\n{table.caption}")
    rows = [dict(zip(table.columns, (format_number(v) if isinstance(v, float) else v
                                     for v in row))) for row in table.rows]
    print_table(rows, list(table.columns))


def _scaling(figures, members: tuple[int, ...]) -> None:
    """Cost per simulated second on ``n_fourbar@N`` for N in ``members``, per adapter."""
    print("\ncost per simulated second on n_fourbar@N (best, dt 1e-3 s, 0.5 s), s/s")
    rows, exponents = figures.scaling_rows(members=members)
    table = {}
    for row in rows:
        table.setdefault(row["adapter"], {"adapter": row["adapter"]})[f"N={row['N']}"] = \
            format_number(row["s_per_sim_s"]) if row["status"] == CaseStatus.OK else row["status"]
    for name, row in table.items():
        row["exponent (N>=4)"] = format_number(exponents[name])
    print_table(list(table.values()), ["adapter", *(f"N={n}" for n in members),
                                       "exponent (N>=4)"])
