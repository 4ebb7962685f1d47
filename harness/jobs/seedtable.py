"""The seed's comparison, run the seed's way (Rouvinen 2003, ch. 7 setup):
integrators RK4, RKN4 and 4th-order Gear (iteration tolerance 1e-5) × stabilisation none /
Baumgarte α = β = 5 / direct violation correction, fixed step Δt = 0.01 s, the four-bar for 4 s and
the slider-crank for 8 s.  Reported per case: maximum and mean constraint violation (m: the
neutral joint gap, or lever × orientation residual; the seed's |Φ| mixes metres with direction
cosines), maximum energy-balance error, wall time (mean of three runs, as the seed) and mean
Newton iterations per step.  Every run is judged by the measuring stick (:func:`mbh._harness.run.case.run_case`,
against the verified reference), so a row's status says whether its answer can be trusted.
"""

from __future__ import annotations

import statistics

from mbh._adapters import get_adapter
from mbh._harness.model import scenario
from mbh._harness.run.case import run_case
from mbh._harness.references.build import reference_trajectory
from mbh._harness.measure.verdict import DEFAULT_BOUNDS, Bounds

SEED_SCENARIOS = ("fourbar_spatial", "slider_crank")
SEED_INTEGRATORS = ("rk4", "rkn4", "bdf4")
SEED_STABILISATIONS = ("none", "baumgarte", "direct")
SEED_STEP = 0.01
#: Gear's iteration tolerance in the seed.
GEAR_TOLERANCE = 1e-5


def seed_method(integrator: str, stabilisation: str) -> str:
    method = f"{integrator}+{stabilisation}"
    return f"{method}:tol={GEAR_TOLERANCE:g}" if integrator.startswith("bdf") else method


def seed_rows(repeats: int = 3, bounds: Bounds = DEFAULT_BOUNDS) -> list[dict]:
    """One row per scenario × integrator × stabilisation, judged within ``bounds``."""
    adapter = get_adapter("inhouse")
    rows = []
    for name in SEED_SCENARIOS:
        mech = scenario.load(name)
        reference = reference_trajectory(mech)
        for integrator in SEED_INTEGRATORS:
            for stabilisation in SEED_STABILISATIONS:
                method = seed_method(integrator, stabilisation)
                runs = [run_case(adapter, mech, method, SEED_STEP, mech.duration, reference, bounds)
                        for _ in range(repeats)]
                metrics = runs[-1].metrics
                steps = max(metrics["steps"], 1)
                rows.append({
                    "scenario": name, "integrator": integrator, "stabilisation": stabilisation,
                    "status": metrics["status"], "reason": metrics["reason"],
                    "max_violation": metrics.get("max_constraint_violation"),
                    "mean_violation": metrics.get("mean_constraint_violation"),
                    "max_energy_error_J": metrics.get("max_energy_error_J"),
                    "wall_time_s": statistics.mean(r.metrics["wall_time_s"] for r in runs),
                    "newton_per_step": metrics["counters"].get("newton_iterations", 0) / steps,
                })
    return rows


def format_rows(rows: list[dict]) -> str:
    """The table as aligned text (numbers in 3 significant digits)."""
    header = ("scenario", "integrator", "stabilisation", "status", "max viol. (m)", "mean viol. (m)",
              "max |ΔE| (J)", "wall (s)", "Newton/step")
    keys = ("scenario", "integrator", "stabilisation", "status", "max_violation", "mean_violation",
            "max_energy_error_J", "wall_time_s", "newton_per_step")
    cells = [[_cell(row[k]) for k in keys] for row in rows]
    widths = [max(len(h), *(len(c[i]) for c in cells)) for i, h in enumerate(header)]
    lines = ["  ".join(h.ljust(w) for h, w in zip(header, widths))]
    lines += ["  ".join(c.ljust(w) for c, w in zip(cell, widths)) for cell in cells]
    return "\n".join(lines)


def _cell(value) -> str:
    if isinstance(value, float):
        return f"{value:.3g}"
    return "—" if value is None else str(value)
