"""Per-case overhead of the campaign executor: warm workers (forked from the template) against cold
ones (a fresh interpreter per case), measured side by side in one run, and the rows compared.

Run:  .venv/bin/python benchmarks/worker_start.py [CAMPAIGN] [--repeats N] [--workers W] [--warm-only]
                                                    [--every K]

Each repeat runs the campaign (default ``smoke``) once warm and once cold, alternately, into
temporary results roots, with the campaign's machine-speed figure.  The first warm run starts the
template, which the later ones find running: a one-off ``mbh run`` pays what the first run pays, a
process that runs campaign after campaign what the later ones pay.  The overhead of a run is
(campaign wall time × workers − Σ case wall times) / cases, s per case: everything that is not
the engines' own stepping (process start, imports, loading compiled code and references, the
measuring stick, storing).  The campaign's stability sweep is left out: its runs are bisection
steps that store no wall time, so their stepping would count as overhead.  The script prints each
run's overhead, the medians and their ratio, then checks that every case's row is the same warm
and cold (every column but the wall times and the run's own ids).  ``--warm-only`` runs the warm
side alone (the nightly's 1,128 cases take ~25 min cold); ``--every K`` keeps every K-th case of
the campaign (the nightly's every fourth: 282 cases, ~1 min warm).  Numbers are measured on the
machine that runs it; nothing is asserted.
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import tempfile
import time

import pandas as pd

from mbh._harness.run.campaign import run_campaign
from mbh._harness.run.executor import usable_cores
from mbh._harness.run.spec import load_campaign

#: Columns that differ between two runs of the same cases by design: times and the run's ids.
MACHINE_COLUMNS = ("run_id", "wall_time_s", "wall_time_per_sim_s", "wall_time_per_step_s",
                   "wall_times_s", "trajectory_file", "reused_from")


def timed_run(campaign, workers: int, warm: bool) -> tuple[float, pd.DataFrame]:
    """(campaign wall time in s, its case rows by case_id) of one run into a temporary root."""
    with tempfile.TemporaryDirectory(prefix="mbh-worker-start-") as root:
        began = time.perf_counter()
        store = run_campaign(campaign, workers=workers, root=root, quiet=True,
                             warm_workers=warm)
        wall = time.perf_counter() - began
        return wall, store.cases().set_index("case_id").sort_index()


def overhead(wall: float, workers: int, cases: pd.DataFrame) -> float:
    """(wall × workers − Σ case wall times) / cases, s per case."""
    return (wall * workers - cases["wall_time_s"].fillna(0).sum()) / len(cases)


def differing_columns(first: pd.DataFrame, second: pd.DataFrame) -> dict[str, int]:
    """Column → number of cases whose values differ (NaN equals NaN), times and ids left out."""
    differ = {}
    for column in first.columns.difference(MACHINE_COLUMNS):
        a, b = first[column], second[column].reindex(first.index)
        same = ((a == b) | (a.isna() & b.isna())).fillna(False)
        if not same.all():
            differ[column] = int((~same).sum())
    return differ


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("campaign", nargs="?", default="smoke")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--workers", type=int, default=usable_cores())
    parser.add_argument("--warm-only", action="store_true", help="no cold runs")
    parser.add_argument("--every", type=int, default=1, help="keep every K-th case")
    args = parser.parse_args()
    campaign = load_campaign(args.campaign)
    campaign = dataclasses.replace(campaign, cases=campaign.cases[::args.every], sweep=None)
    sides = (True,) if args.warm_only else (True, False)
    results = {warm: [] for warm in sides}
    for repeat in range(args.repeats):
        for warm in sides:
            wall, cases = timed_run(campaign, args.workers, warm)
            results[warm].append((wall, cases))
            print(f"run {repeat + 1} {'warm' if warm else 'cold'}: {len(cases)} cases, "
                  f"{wall:.1f} s wall on {args.workers} workers, Σ case wall times "
                  f"{cases['wall_time_s'].fillna(0).sum():.2f} s, overhead "
                  f"{overhead(wall, args.workers, cases):.3f} s per case", flush=True)
    medians = {warm: statistics.median(overhead(wall, args.workers, cases)
                                       for wall, cases in runs)
               for warm, runs in results.items()}
    walls = {warm: statistics.median(wall for wall, _ in runs) for warm, runs in results.items()}
    if args.warm_only:
        print(f"median overhead per case: warm {medians[True]:.3f} s; median campaign wall "
              f"{walls[True]:.1f} s")
        return
    print(f"median overhead per case: warm {medians[True]:.3f} s, cold {medians[False]:.3f} s "
          f"(warm/cold {medians[True] / medians[False]:.3f}); median campaign wall: warm "
          f"{walls[True]:.1f} s, cold {walls[False]:.1f} s")
    differ = differing_columns(results[True][0][1], results[False][0][1])
    print("rows warm vs cold: " + ("identical in every column but the wall times and ids"
                                   if not differ else f"DIFFER in {differ}"))


if __name__ == "__main__":
    main()
