"""Convergence orders of the in-house fixed-step integrators in joint coordinates (``coords=joint``)
beside the same methods in absolute coordinates (issue 44; docs/measurements.md, "Joint
coordinates").

Run:  .venv/bin/python benchmarks/joint_orders.py [--scene fourbar fourbar_spatial slider_crank]
      [--treatment direct] [--only rk4 bdf2 ...]

For each scene and fixed-step integrator it runs ``INTEGRATOR+TREATMENT`` (implicit methods with
``tol=1e-10``) over 1 s at three steps in the method's asymptotic range (those of
``tests/adapters/inhouse/test_dynamics.py``, where the absolute orders are checked; rk8 at four
steps over 4 s), measures the
largest error of the main output (the first declared: the crank angle) against the scene's verified reference on the 10 ms grid, and prints the
least-squares slope of log error over log step with the errors, joint then absolute.  A run that is
not ``ok`` prints its status.  Nothing here is asserted; the figures are the machine's and the
versions' that run it (the orders are not).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from mbh._adapters import get_adapter  # noqa: E402
from mbh._adapters.integrators import (integrator_class, integrator_names,  # noqa: E402
                                      integrator_params)
from mbh._harness.measure.metrics import case_metrics  # noqa: E402
from mbh._harness.model import scenario  # noqa: E402
from mbh._harness.model.timegrid import sample_times  # noqa: E402
from mbh._harness.run.spec import main_output  # noqa: E402
from mbh._harness.references.build import reference_trajectory  # noqa: E402

#: Steps (s) in each method's asymptotic range on the four-bar over 1 s, every one dividing the
#: 10 ms evaluation grid (test_dynamics.py's ORDERS_FAST, ORDERS_SLOW and its rk8 test, whose
#: steps keep rk8's error above the reference's accuracy over 4 s).  Methods not named take the
#: last entry.
STEPS = {
    "euler": [2e-3, 1e-3, 5e-4], "symplectic-euler": [2e-3, 1e-3, 5e-4],
    "heun": [1e-2, 5e-3, 2.5e-3], "rk5": [1e-2, 5e-3, 2.5e-3], "rk8": [5e-3, 1e-2 / 3, 2.5e-3, 2e-3],
    "ab1": [1e-2, 5e-3, 2.5e-3], "ab2": [1e-2, 5e-3, 2.5e-3], "ab3": [1e-2, 5e-3, 2.5e-3],
    "am2": [1e-2, 5e-3, 2.5e-3], "am3": [1e-2, 5e-3, 2.5e-3], "am4": [1e-2, 5e-3, 2.5e-3],
    "abm4": [1e-2, 5e-3, 2.5e-3],
    "am1": [2e-3, 1e-3, 5e-4], "bdf1": [2e-3, 1e-3, 5e-4], "bdf2": [2e-3, 1e-3, 5e-4],
    "bdf3": [2e-3, 1e-3, 5e-4], "bdf4": [2e-3, 1e-3, 5e-4],
    "": [5e-3, 2.5e-3, 1.25e-3],
}
#: Run length (s) where it is not 1 s: rk8 over 4 s, as test_dynamics.py measures it.
T_END = {"rk8": 4.0}
INHOUSE = get_adapter("inhouse")


def fixed_step_integrators() -> list[str]:
    """The in-house integrators with a fixed step (the adaptive SciPy ones left out)."""
    return [name for name in integrator_names() if not integrator_class(name).adaptive]


def method_text(integrator: str, treatment: str, coords: str) -> str:
    """The method at the Newton tolerance of test_dynamics.py for the implicit ones; absolute
    runs on the generic compiled loop where there is one (the same numbers as the generated one,
    without compiling functions for each scene and method)."""
    options = [f"coords={coords}"] + (["tol=1e-10"] if "tol" in integrator_params(integrator)
                                      else [])
    text = f"{integrator}+{treatment}:{','.join(options)}"
    if coords == "absolute" and "loop" in INHOUSE.method_spec(text)[1]:
        text += ",loop=compiled"
    return text


def errors_of(mech, reference, method: str, steps: list[float],
              t_end: float) -> list[float] | str:
    """Largest main-output error at each step over ``t_end`` (s), or the first status that is
    not ``ok``."""
    errors = []
    for dt in steps:
        trajectory = INHOUSE.simulate(mech, method, dt, t_end, sample_times(dt, t_end))
        if trajectory.status != "ok":
            return f"{trajectory.status} at dt {dt:g}: {trajectory.reason}"
        metrics = case_metrics(mech, trajectory, reference)
        errors.append(metrics["output_errors"][main_output(mech)])
    return errors


def slope(steps: list[float], errors: list[float]) -> float:
    return float(np.polyfit(np.log(steps), np.log(errors), 1)[0])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", nargs="+", default=["fourbar", "fourbar_spatial", "slider_crank"])
    parser.add_argument("--treatment", default="direct")
    parser.add_argument("--only", nargs="+", default=None)
    parser.add_argument("--steps", nargs="+", type=float, default=None,
                        help="steps (s) for every method instead of STEPS")
    args = parser.parse_args()
    names = args.only or fixed_step_integrators()
    for scene in args.scene:
        mech = scenario.load(scene)
        reference = reference_trajectory(mech)
        for integrator in names:
            steps = args.steps or STEPS.get(integrator, STEPS[""])
            cells = []
            for coords in ("joint", "absolute"):
                found = errors_of(mech, reference, method_text(integrator, args.treatment, coords),
                                  steps, T_END.get(integrator, 1.0))
                cells.append(found if isinstance(found, str) else
                             f"{slope(steps, found):5.2f} ({', '.join(f'{e:.2e}' for e in found)})")
            print(f"{scene:16s} {integrator:17s} steps {', '.join(f'{s:.3g}' for s in steps):20s} "
                  f"joint {cells[0]}  absolute {cells[1]}", flush=True)


if __name__ == "__main__":
    main()
