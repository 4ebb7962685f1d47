"""Methods of the Exudyn adapter: their parameters (Exudyn's own defaults and the measured best),
the checks of those parameters, and the Exudyn ``SimulationSettings`` of one run.

Methods
-------
``default``
    Exudyn's ``SolveDynamic`` defaults at fixed steps: generalized-α (index 3), spectral radius
    0.9, modified Newton, relative/absolute tolerance 1e-8/1e-10, at most 25 iterations.
``newmark``
    Newmark (``useNewmark``) with Exudyn's default β = 1/4, γ = 1/2, index 3; ``index2=true``
    switches to velocity-level constraints (Exudyn allows index 2 only with Newmark).
``trapezoidal``
    What Exudyn's ``TrapezoidalIndex2`` sets: Newmark β = 1/4, γ = 1/2 with index-2 constraints.
``best``
    The most accurate settings measured at a given step (see :data:`_BEST`).

Exudyn's explicit solvers are not offered: with ``eliminateConstraints=True`` they refuse these
constraints, and with ``eliminateConstraints=False`` they silently ignore the joints.
"""

from __future__ import annotations

import exudyn as exu
import numpy as np

#: Newton and integrator settings shared by every method; the values are Exudyn's defaults for
#: ``SolveDynamic`` (``exu.SimulationSettings().timeIntegration``), read from exudyn 1.13.6.
_COMMON_PARAMS = {
    "rtol": 1e-8,              # newton.relativeTolerance
    "atol": 1e-10,             # newton.absoluteTolerance
    "max_iter": 25,            # newton.maxIterations
    "modified_newton": True,   # newton.useModifiedNewton
    "rotation": "ep",          # spatial nodes: "ep" (NodeRigidBodyEP) or "rotvec" (RotVecLG)
    "ignore_singular": False,  # ignoreSingularJacobian with EigenDense (redundant constraints)
}
_ROTATIONS = ("ep", "rotvec")
#: Generalized-α (index 3): Exudyn's default spectralRadius.
_GENALPHA_PARAMS = {"rho_inf": 0.9, **_COMMON_PARAMS}
#: Newmark: Exudyn's default newmarkBeta/newmarkGamma (undamped trapezoidal rule), index 3.
_NEWMARK_PARAMS = {"beta": 0.25, "gamma": 0.5, "index2": False, **_COMMON_PARAMS}
#: The most accurate settings measured (see tests/adapters/exudyn/test_exudyn_adapter.py),
#: re-chosen 2026-11-25.
#: Rule: the smallest max |crank angle − verified reference| (the main output) in the most of the
#: 8 cases fourbar, fourbar_spatial, slider_crank, slider_crank_planar × dt 1e-3, 1e-4 s over each
#: scene's duration (4, 4, 8, 4 s), among candidates whose every one of those runs the measuring
#: stick (``harness.measure.verdict.judge``) finds ok; a winner that ends the shipped hard scenes earlier
#: than the incumbent is weighed against its gain.  Measured, Newton rtol = atol = 1e-12, full
#: Newton: error (rad) / max joint gap (m) / max velocity violation (m/s) —
#:
#: case, dt (s)    gen.-α ρ∞ 0.9 (best)      trapezoidal, ep           trapezoidal, rotvec
#: fourbar 1e-3    7.16e-4 / 2e-15 / 1.2e-3  2.66e-4 / 3.2e-5 / 7e-12  2.66e-4 / 3.2e-5 / 7e-12
#: fourbar 1e-4    7.16e-6 / 2e-15 / 1.2e-5  2.66e-6 / 3.2e-7 / 1e-11  2.66e-6 / 3.2e-7 / 1e-11
#: fb_spatial 1e-3 7.22e-4 / 9e-13 / 1.2e-3  2.32e-4 / 4.7e-5 / 7e-5   2.58e-4 / 3.2e-5 / 5e-12
#: fb_spatial 1e-4 7.22e-6 / 5e-15 / 1.2e-5  2.33e-6 / 4.7e-7 / 1e-6   2.58e-6 / 3.2e-7 / 6e-12
#: sl_crank 1e-3   6.42e-2 / 7e-13 / 2.3e-3  1.85e-2 / 3.2e-3 / 0.53 † 2.95e-2 / 3.0e-4 / 4e-11
#: sl_crank 1e-4   6.43e-4 / 4e-14 / 2.2e-5  1.88e-4 / 3.2e-5 / 5.3e-3 2.96e-4 / 3.0e-6 / 2e-10
#: sc_planar 1e-3  6.84e-2 / 2e-15 / 1.3e-2  3.10e-2 / 1.6e-4 / 1e-12  3.10e-2 / 1.6e-4 / 1e-12
#: sc_planar 1e-4  6.74e-4 / 2e-15 / 1.4e-4  3.08e-4 / 1.5e-6 / 1e-12  3.08e-4 / 1.5e-6 / 1e-12
#:
#: † judged failed: joint orientation violation 5.03e-3 rad > 5e-3 at 6.43 s (the Euler
#: parameters' normalisation is enforced at velocity level only and drifts).  fb_spatial,
#: sl_crank, sc_planar: fourbar_spatial, slider_crank, slider_crank_planar.
#: Generalized-α with ρ∞ = 1.0 and Newmark index 3 (undamped index 3, tight) stopped ("reduction
#: of step size reached minimum step size") in 6 of the 8 cases.  The index-2 trapezoidal rule with
#: rotation vectors wins the rule (2.2–2.8× smaller error in all 8 cases) but on the hard scenes
#: (over min(duration, 4 s); failure times in s, trapezoidal rotvec against generalized-α) it ends
#: bricard at 0.004 / 0.0002 (dt 1e-3 / 1e-4) against 0.485 / ok, parallelogram_fourbar at 0.537
#: / 0.538 against ok / 2.15, double_fourbar at 0.713 / 0.714 against 2.66 / 0.714; andrews (dt
#: 1e-4) is ok with both (errors 4.1e-3 against 8.7e-3).  A factor ~2.5 on smooth scenes does not
#: buy a `best` that fails Bricard within its first steps, so generalized-α stays: it holds the
#: position constraints to round-off (index 3) and trades the velocity-level violation above (up
#: to 1.3e-2 m/s at 1e-3), which shrinks 100× per 10× smaller step.  Steps below ~2.5e-5 s
#: lose digits in the index-3 Newton iteration: the start accelerations of generated mechanisms
#: were measured 4.5e-3 m/s² off at 1e-5 s (the iteration stops at atol = 1e-12; 1e-14 cures
#: that case) and 1.0e-4 relative off at 2e-5 s (not cured by atol), against ≤ 1.1e-5 at 2.5e-5 s
#: (tests/engines/test_generated_mechanisms.py).
_BEST = {**_GENALPHA_PARAMS, "rtol": 1e-12, "atol": 1e-12, "modified_newton": False,
         "ignore_singular": True}


def _validate_params(params: dict) -> None:
    if params.get("rotation", "ep") not in _ROTATIONS:
        raise ValueError(f"parameter 'rotation' must be one of {', '.join(_ROTATIONS)}, "
                         f"got {params['rotation']!r}")
    if "rho_inf" in params and not 0.0 <= params["rho_inf"] <= 1.0:
        raise ValueError(f"parameter 'rho_inf' must lie in [0, 1], got {params['rho_inf']!r}")
    if "gamma" in params and not (params["gamma"] >= 0.5 and params["beta"] > 0):
        raise ValueError(f"parameters 'beta' > 0 and 'gamma' >= 1/2 required, got "
                         f"beta={params['beta']!r}, gamma={params['gamma']!r}")
    for key in ("rtol", "atol"):
        if not params[key] > 0:
            raise ValueError(f"parameter {key!r} must be positive, got {params[key]!r}")
    if params["max_iter"] < 1:
        raise ValueError(f"parameter 'max_iter' must be at least 1, got {params['max_iter']!r}")


# ---------------------------------------------------------------------------------------------
# settings


def _write_period(indices: np.ndarray, dt: float) -> float:
    """Sensor period: the largest multiple of ``dt`` that hits every sampled step, s."""
    steps = int(np.gcd.reduce(indices[indices > 0])) if np.any(indices > 0) else 1
    return steps * dt


def _settings(params: dict, dt: float, steps: int,
              write_period: float) -> exu.SimulationSettings:
    """Exudyn settings for ``steps`` fixed steps of ``dt``: generalized-α when ``params`` has
    ``rho_inf``, Newmark otherwise."""
    settings = exu.SimulationSettings()
    settings.solution.file.write = False
    settings.solution.sensors.writePeriod = write_period
    settings.show.statistics = False
    settings.show.computationTime = False
    if params["ignore_singular"]:
        # only honoured by Eigen's full-pivot LU: with the default EXUdense it has no effect
        settings.linearSolver.solverType = exu.LinearSolverType.EigenDense
        settings.linearSolver.ignoreSingularJacobian = True
    integration = settings.timeIntegration
    integration.verboseMode = 0
    integration.startTime = 0.0
    integration.endTime = steps * dt
    integration.numberOfSteps = steps
    integration.adaptiveStep = False
    integration.automaticStepSize = False
    newton = integration.newton
    newton.relativeTolerance = params["rtol"]
    newton.absoluteTolerance = params["atol"]
    newton.maxIterations = params["max_iter"]
    newton.useModifiedNewton = params["modified_newton"]
    alpha = integration.generalizedAlpha
    integration.solverType = exu.DynamicSolverType.GeneralizedAlpha
    if "rho_inf" in params:
        alpha.spectralRadius = params["rho_inf"]
    else:
        alpha.useNewmark = True
        alpha.newmarkBeta = params["beta"]
        alpha.newmarkGamma = params["gamma"]
        alpha.useIndex2Constraints = params["index2"]
    return settings


def _unenforced_solver(settings: exu.SimulationSettings) -> exu.MainSolverExplicit:
    """The trap the tests must catch: explicit RK4 that drops the constraints without a word."""
    settings.timeIntegration.solverType = exu.DynamicSolverType.RK44
    settings.timeIntegration.explicit.eliminateConstraints = False
    return exu.MainSolverExplicit()
