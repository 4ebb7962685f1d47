"""The Exudyn adapter: the harness's contract over :mod:`.methods` and :mod:`.system`.  ``build``
only checks that Exudyn can represent the mechanism; every ``simulate`` builds a fresh
:class:`~adapters.exudyn_adapter.system.ExudynSystem`, with Exudyn's console output off.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass

import exudyn as exu
import numpy as np

from adapters.base import Adapter, MethodSpec, UnsupportedCase
from adapters.exudyn_adapter.methods import (
    _BEST,
    _GENALPHA_PARAMS,
    _NEWMARK_PARAMS,
    _settings,
    _unenforced_solver,
    _validate_params,
    _write_period,
)
from adapters.exudyn_adapter.system import ExudynSystem, _describe
from harness.model import PLANAR_JOINT_TYPES, Mechanism
from harness.trajectory import Trajectory


@dataclass(frozen=True)
class ExudynModel:
    """What :meth:`ExudynAdapter.build` returns: the mechanism, checked for Exudyn.

    Each :meth:`ExudynAdapter.simulate` call builds a fresh Exudyn system from it, so one model
    serves any number of runs.

    Attributes
    ----------
    mechanism : Mechanism
    _unenforced_joints : bool
        Test-only hook: run Exudyn's explicit RK4 with ``eliminateConstraints=False``, the known
        trap in which Exudyn ignores every joint while reporting success.  Never offered as a method.
    """

    mechanism: Mechanism
    _unenforced_joints: bool = False


class ExudynAdapter(Adapter):
    """Exudyn (redundant absolute coordinates, implicit index-3/index-2 integrators)."""

    name = "exudyn"

    def version(self) -> str:
        return f"exudyn {exu.__version__}"

    def methods(self) -> list[MethodSpec]:
        return [
            MethodSpec("default", "Exudyn SolveDynamic defaults at fixed steps: generalized-alpha "
                       "(index 3), spectral radius 0.9, modified Newton", dict(_GENALPHA_PARAMS)),
            MethodSpec("newmark", "Newmark (useNewmark), index 3 unless index2=true; "
                       "gamma > 1/2 damps and is first order", dict(_NEWMARK_PARAMS)),
            MethodSpec("trapezoidal", "Exudyn TrapezoidalIndex2: undamped Newmark (beta=1/4, "
                       "gamma=1/2) with index-2 constraints", {**_NEWMARK_PARAMS, "index2": True}),
            MethodSpec("best", "most accurate measured: generalized-alpha (index 3), full Newton, "
                       "tolerances 1e-12", dict(_BEST)),
        ]

    def build(self, mechanism: Mechanism) -> ExudynModel:
        """Check that Exudyn can represent ``mechanism``.

        Raises
        ------
        UnsupportedCase
            A planar scenario with a joint type Exudyn has no 2D joint for.
        """
        if mechanism.planar:
            for joint in mechanism.joints:
                if joint.type not in PLANAR_JOINT_TYPES:
                    raise UnsupportedCase(f"planar joint {joint.name!r} of type {joint.type!r}: "
                                          f"Exudyn 2D joints are {', '.join(PLANAR_JOINT_TYPES)}")
        return ExudynModel(mechanism)

    def simulate(self, model: ExudynModel, method: str, dt: float, t_end: float,
                 sample_times: np.ndarray) -> Trajectory:
        """Run ``model`` with ``method`` at the fixed step ``dt`` up to ``t_end``.

        Parameters
        ----------
        model : ExudynModel
        method : str
            ``NAME[:key=value,...]``, see :meth:`methods`.
        dt, t_end : float
            Step and end time, s; ``round(t_end / dt)`` steps are taken.
        sample_times : ndarray, shape (n_samples,)
            Integer multiples of ``dt`` (0 included); the state after step ``round(t / dt)`` is
            recorded for each.

        Returns
        -------
        Trajectory
            ``failed`` when Exudyn raises (e.g. Newton does not converge), ``diverged`` when the
            states stop being finite; the samples reached are kept.
        """
        spec, params = self.method_spec(method)
        _validate_run(dt, t_end, sample_times)
        _validate_params(params)
        mech = model.mechanism
        steps = round(t_end / dt)
        indices = np.rint(np.asarray(sample_times, dtype=float) / dt).astype(int)
        notes = _notes(mech, spec.name, params)
        with _quiet():
            try:
                system = ExudynSystem(mech, params["rotation"])
                settings = _settings(params, dt, steps, _write_period(indices, dt))
            except Exception as error:  # engine exceptions are results (DESIGN rule 5)
                return Trajectory.empty(len(mech.bodies), status="failed",
                                        reason=f"model rejected: {_describe(error)}",
                                        failure_time=0.0, notes=notes)
            solver = _unenforced_solver(settings) if model._unenforced_joints \
                else exu.MainSolverImplicitSecondOrder()
            run = system.run(solver, settings, dt)
        return system.trajectory(run, indices, dt, notes)


# ---------------------------------------------------------------------------------------------
# validation


def _validate_run(dt: float, t_end: float, sample_times) -> None:
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be a positive finite step, got {dt!r}")
    if not (np.isfinite(t_end) and round(t_end / dt) >= 1):
        raise ValueError(f"t_end must be a finite time of at least one step dt, got {t_end!r}")
    times = np.asarray(sample_times, dtype=float)
    if times.ndim != 1 or times.size == 0:
        raise ValueError("sample_times must be a non-empty 1-D array of times")
    k = times / dt
    if np.any(np.abs(k - np.rint(k)) > 1e-6) or np.any(times < 0) or np.any(times > t_end + dt / 2):
        raise ValueError("sample_times must be integer multiples of dt within [0, t_end]")


def _notes(mech: Mechanism, name: str, params: dict) -> list[str]:
    if mech.planar:
        return [f"exudyn {name}: planar model with NodeRigidBody2D "
                f"(parameter 'rotation' is not used)"]
    node = "NodeRigidBodyEP" if params["rotation"] == "ep" else "NodeRigidBodyRotVecLG"
    return [f"exudyn {name}: spatial model with {node}"]


@contextlib.contextmanager
def _quiet():
    """Keep Exudyn from printing to the console for the duration of a run."""
    previous = exu.config.printToConsole
    exu.config.printToConsole = False
    try:
        yield
    finally:
        exu.config.printToConsole = previous
