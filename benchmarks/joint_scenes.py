"""Every shipped scene in joint coordinates beside absolute coordinates, judged as a campaign judges
it (issue 44; docs/measurements.md, "Joint coordinates").

Run:  .venv/bin/python benchmarks/joint_scenes.py [--dt 1e-3] [--t-end 1.0]
      [--methods rk4+direct:coords=joint rk4+direct ...] [--only fourbar ...]

For each shipped scene and method it runs one case with :func:`mbh.run_case` over the scene's
whole duration (or ``--t-end`` s) at ``--dt`` and prints its verdict (``status``, and the reason
when not ``ok``), the main output's largest error against the verified reference, the stick's
largest joint gap, the run's placed passages and re-partitions, and the notes that name the
model's passages.  Nothing here is asserted; the figures are the machine's and the versions' that
run it.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import mbh  # noqa: E402

METHODS = ("rk4+direct:coords=joint", "rk4+direct", "rk4+partition:coords=joint",
           "rk4+partition")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dt", type=float, default=1e-3)
    parser.add_argument("--t-end", type=float, default=None)
    parser.add_argument("--methods", nargs="+", default=list(METHODS))
    parser.add_argument("--only", nargs="+", default=None)
    args = parser.parse_args()
    for scene in args.only or mbh.scenario_names():
        duration = mbh.load_scenario(scene).duration
        t_end = min(args.t_end, duration) if args.t_end else duration
        for method in args.methods:
            began = time.perf_counter()
            try:
                result = mbh.run_case(scene, "inhouse", method, dt=args.dt, t_end=t_end)
            except mbh.CaseInputError as error:  # a step that does not divide the scene's grid
                print(f"{scene:22s} {method:28s} not run: {error}")
                continue
            row = result.row or {}
            counters = result.trajectory.counters or {}
            passages = [part for note in result.trajectory.notes for part in note.split("; ")
                        if "passage" in part]
            print(f"{scene:22s} {method:28s} {t_end:5g} s {result.status:10s} "
                  f"error {row.get('main_output_error', float('nan')):.3g} "
                  f"gap {result.metrics.get('max_constraint_violation', float('nan')):.2g} "
                  f"passages {counters.get('passages', '-')} "
                  f"repartitions {counters.get('repartitions', '-')} "
                  f"({time.perf_counter() - began:.1f} s)", flush=True)
            if result.status != "ok":
                print(f"    reason: {result.reason}")
            for note in passages:
                print(f"    note: {note}")


if __name__ == "__main__":
    main()
