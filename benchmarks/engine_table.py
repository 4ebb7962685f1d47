"""Accuracy and cost of every engine's methods against the verified reference.

Run:  .venv/bin/python benchmarks/engine_table.py [--adapters a,b] [--scenarios s,t]
                                                  [--dts 1e-2,1e-3,1e-4] [--json out.json]

Per scenario, adapter, method and step: status, maximum crank-angle error against the reference,
maximum joint-equation violation and joint gap (measured by the harness from the reported body
states), maximum energy-balance error, and microseconds per step.  Also prints, for the steps
given, how many significant digits of the final crank angle each pair of `best` methods shares.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math

from adapters import adapter_names, get_adapter
from adapters.base import UnsupportedCase
from harness import scenario
from harness.metrics import case_metrics
from harness.reference import reference_trajectory
from harness.sampling import sample_times

METHODS = {"inhouse": ["default", "best"], "mujoco": ["default", "best"],
           "pybullet": ["default", "best"], "pinocchio": ["default", "best"],
           "exudyn": ["default", "best"]}


def run_case(adapter, mech, method, dt):
    try:
        model = adapter.build(mech)
    except UnsupportedCase as error:
        return {"status": "unsupported", "reason": str(error)}
    trajectory = adapter.simulate(model, method, dt, mech.duration, sample_times(dt, mech.duration))
    metrics = case_metrics(mech, trajectory, reference_trajectory(mech))
    metrics["us_per_step"] = 1e6 * trajectory.wall_time_s / max(trajectory.steps, 1)
    return metrics


def agreeing_digits(a: float, b: float) -> float:
    """−log10 of the relative difference (significant digits shared), capped at 16."""
    if a == b:
        return 16.0
    return min(16.0, -math.log10(abs(a - b) / max(abs(a), abs(b))))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--adapters", default=",".join(adapter_names()))
    parser.add_argument("--scenarios", default=",".join(scenario.scenario_names()))
    parser.add_argument("--dts", default="1e-2,1e-3,1e-4")
    parser.add_argument("--json", default=None, help="also write every row to this file")
    args = parser.parse_args()
    rows = []
    header = (f"{'scenario':20s} {'adapter':9s} {'method':8s} {'dt':>7s} {'status':10s} "
              f"{'crank err':>10s} {'max |Φ|':>9s} {'gap (m)':>9s} {'|ΔE| (J)':>9s} {'µs/step':>8s}")
    print(header)
    for name in args.scenarios.split(","):
        mech = scenario.load(name)
        for adapter_name in args.adapters.split(","):
            adapter = get_adapter(adapter_name)
            for method, dt in itertools.product(METHODS[adapter_name],
                                                [float(d) for d in args.dts.split(",")]):
                metrics = run_case(adapter, mech, method, dt)
                row = {"scenario": name, "adapter": adapter_name, "method": method, "dt": dt,
                       **metrics}
                rows.append(row)
                err = metrics.get("output_errors", {}).get("crank_angle", float("nan"))
                print(f"{name:20s} {adapter_name:9s} {method:8s} {dt:7.0e} {metrics['status']:10s} "
                      f"{err:10.2e} {metrics.get('max_constraint_violation', float('nan')):9.1e} "
                      f"{metrics.get('max_joint_gap_m', float('nan')):9.1e} "
                      f"{metrics.get('max_energy_error_J', float('nan')):9.2e} "
                      f"{metrics.get('us_per_step', float('nan')):8.0f}", flush=True)
    _print_digits(rows)
    if args.json:
        with open(args.json, "w", encoding="utf-8") as handle:
            json.dump(rows, handle, indent=1, default=str)


def _print_digits(rows: list[dict]) -> None:
    finals = {}
    for row in rows:
        if row["method"] == "best" and row.get("status") == "ok":
            finals[(row["scenario"], row["dt"], row["adapter"])] = row["outputs"]["crank_angle"]
    keys = sorted({(s, dt) for s, dt, _ in finals})
    for scenario_name, dt in keys:
        engines = sorted(a for s, d, a in finals if (s, d) == (scenario_name, dt))
        print(f"\nagreeing significant digits of the final crank angle, best methods, "
              f"{scenario_name} dt={dt:g}:")
        for a, b in itertools.combinations(engines, 2):
            digits = agreeing_digits(finals[(scenario_name, dt, a)], finals[(scenario_name, dt, b)])
            print(f"  {a:9s} vs {b:9s} {digits:5.1f}")


if __name__ == "__main__":
    main()
