"""Every engine's ``best`` on overconstrained and flat-bodied loops, against the verified
reference (issue "Trust 3", part 2; docs/measurements.md, "Engine settings on hard loops").

Run:  .venv/bin/python benchmarks/hard_loops.py [--dt 1e-3 1e-4] [--only bennett ...]

Per mechanism and step it prints, for each engine, the main output's error against the reference
(max over the samples; rad), its ratio to the best engine's, the status, and the engine
limit its row names: the note (or, for a failed run, the reason) that starts with
``engine limit:``, cut to one line.  A row more than 10× off the best (or not ``ok``) without a
named limit is marked ``!``.  Mechanisms: ``bennett`` and ``fourbar_4r``, ``flat_parallelogram``,
``fourbar_rsrr`` from ``tests/helpers.py``, the shipped ``bricard`` over 1 s.  References are
built once and cached (a new scene's takes a few seconds).  Nothing here is asserted; the
numbers are the machine's and the versions' that run it.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # tests.helpers

import mbh  # noqa: E402
from tests.helpers import (  # noqa: E402
    bennett_linkage,
    flat_parallelogram,
    parallel_revolute_fourbar,
    rsrr_fourbar,
)

ENGINES = ("inhouse", "mujoco", "pinocchio", "exudyn", "pybullet")
#: Mechanism name → (builder, t_end in s).
MECHANISMS = {
    "bennett": (bennett_linkage, 1.0),
    "fourbar_4r": (parallel_revolute_fourbar, 1.0),
    "bricard": (lambda: mbh.load_scenario("bricard"), 1.0),
    "flat_parallelogram": (flat_parallelogram, 0.4),
    "fourbar_rsrr": (rsrr_fourbar, 1.0),
}
#: Prefix of the notes (and failure reasons) that name an engine's limit.
LIMIT = "engine limit:"
#: Ratio to the best engine beyond which a row must name a limit.
FACTOR = 10.0


def main_error(mech, result) -> float:
    """The main output's error against the reference (nan without samples)."""
    errors = result.metrics.get("output_errors") or {}
    return errors.get(mech.outputs[0].name, math.nan)


def named_limit(result) -> str:
    """The row's limit note, or its reason when that names the limit ('' when neither does)."""
    texts = result.trajectory.notes
    for text in [result.reason, *texts] if result.status != "ok" else texts:
        if LIMIT in text:
            return text[text.index(LIMIT):]
    return ""


def measure(name: str, dt: float) -> list[dict]:
    build, t_end = MECHANISMS[name]
    mech = build()
    rows = []
    for engine in ENGINES:
        began = time.perf_counter()
        result = mbh.run_case(mech, engine, "best", dt=dt, t_end=t_end)
        rows.append({"engine": engine, "status": str(result.status),
                     "failure_time": result.trajectory.failure_time,
                     "error": main_error(mech, result), "limit": named_limit(result),
                     "reason": result.reason, "seconds": time.perf_counter() - began})
    return rows


def show(name: str, dt: float, rows: list[dict]) -> None:
    ok = [row["error"] for row in rows if row["status"] == "ok" and math.isfinite(row["error"])]
    best = min(ok) if ok else math.nan
    print(f"\n{name}, dt {dt:g} s, t_end {MECHANISMS[name][1]:g} s (best error {best:.2g})")
    print(f"  {'engine':<10} {'error':>9} {'ratio':>9}  {'status':<12} limit named")
    for row in rows:
        ratio = row["error"] / best if row["status"] == "ok" else math.nan
        status = row["status"] + (f" {row['failure_time']:.3g}s"
                                  if row["failure_time"] is not None else "")
        off = row["status"] != "ok" or ratio > FACTOR
        flag = "!" if off and not row["limit"] and row["status"] != "unsupported" else " "
        text = row["limit"] or (row["reason"] if row["status"] != "ok" else "")
        text = " ".join(text.split())
        print(f"{flag} {row['engine']:<10} {row['error']:>9.2g} {ratio:>9.3g}  {status:<12} "
              f"{text[:150]}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--dt", type=float, nargs="+", default=[1e-3])
    parser.add_argument("--only", nargs="+", choices=list(MECHANISMS), default=list(MECHANISMS))
    args = parser.parse_args()
    for name in args.only:
        for dt in args.dt:
            show(name, dt, measure(name, dt))


if __name__ == "__main__":
    main()
