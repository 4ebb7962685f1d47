"""The MuJoCo adapter: the harness's contract over :mod:`.build`, :mod:`.state`, :mod:`.methods`
and :mod:`.stepping`, the run loop that samples body states and turns failures into statuses, and
:func:`export_mjcf`.
"""

from __future__ import annotations

import time

import mujoco
import numpy as np

from adapters.base import Adapter, MethodSpec
from adapters.mujoco_adapter.build import MujocoModel, build_model
from adapters.mujoco_adapter.methods import STAGES, _check_params, _configured, _method_specs
from adapters.mujoco_adapter.state import _body_states, _start
from adapters.mujoco_adapter.stepping import _advance
from harness.initial import initial_state
from harness.model import Mechanism
from harness.trajectory import BodyStates, Trajectory


def _sample_steps(dt: float, t_end: float, sample_times) -> tuple[np.ndarray, int]:
    """Step index of each sample time and the total number of steps.

    Raises
    ------
    ValueError
        Naming ``dt``, ``t_end`` or ``sample_times`` when they are not usable.
    """
    if not dt > 0.0:
        raise ValueError(f"dt must be > 0, got {dt!r}")
    if not t_end > 0.0:
        raise ValueError(f"t_end must be > 0, got {t_end!r}")
    times = np.asarray(sample_times, dtype=float)
    steps = np.rint(times / dt).astype(int)
    n_steps = int(round(t_end / dt))
    if times.ndim != 1 or np.any(np.abs(steps * dt - times) > 1e-9 * np.maximum(1.0, times)):
        raise ValueError("sample_times must be a 1-D array of integer multiples of dt")
    if np.any(np.diff(steps) < 0) or np.any(steps < 0) or np.any(steps > n_steps):
        raise ValueError("sample_times must be increasing and lie in [0, t_end]")
    return steps, n_steps


def _notes(built: MujocoModel, model: mujoco.MjModel) -> list[str]:
    """Facts a reader of a run must know."""
    notes = []
    redundant = built.tree.redundant_closure_equations
    if redundant > 0:
        notes.append(f"{redundant} redundant closure equation(s)")
    if model.neq:
        solref = ", ".join(f"{value:g}" for value in model.eq_solref[0])
        solimp = ", ".join(f"{value:g}" for value in model.eq_solimp[0])
        notes.append(f"equality solref ({solref}), solimp ({solimp}); MuJoCo's refsafe clamps "
                     f"the time constant to >= 2·dt")
    if built.loads.moving:
        notes.append("pose-dependent loads (cut-joint actuation, off-centre forces) are "
                     "recomputed once per step and held constant within it")
    return notes


# --------------------------------------------------------------------------------------------
# The adapter


class MujocoAdapter(Adapter):
    """MuJoCo through its spec API (the model: :mod:`.build`; the methods: :mod:`.methods`)."""

    name = "mujoco"

    def version(self) -> str:
        return f"mujoco {mujoco.__version__}"

    def methods(self) -> list[MethodSpec]:
        return _method_specs()

    def build(self, mechanism: Mechanism) -> MujocoModel:
        """Compile ``mechanism``; raises :class:`UnsupportedCase` for unclosable cut joints."""
        return build_model(mechanism)

    def simulate(self, model: MujocoModel, method: str, dt: float, t_end: float,
                 sample_times) -> Trajectory:
        """Run ``method`` at step ``dt`` (s) to ``t_end`` (s) from the harness's initial state.

        Returns a :class:`Trajectory` sampled after step ``round(t / dt)`` of each sample time;
        ``diverged`` (with ``failure_time``) when MuJoCo raises a bad-qpos/qvel/qacc warning,
        ``failed`` when the engine raises.  Raises ValueError for an unknown method, a bad
        parameter or unusable times.
        """
        _, params = self.method_spec(method)
        _check_params(params)
        steps, n_steps = _sample_steps(dt, t_end, sample_times)
        return _Run(model, params, dt).run(np.asarray(sample_times, dtype=float), steps, n_steps)


class _Run:
    """One simulation: the configured model, its data and the samples collected so far."""

    def __init__(self, built: MujocoModel, params: dict, dt: float):
        self.built, self.dt = built, dt
        self.model = _configured(built.model, params, dt)
        self.data = mujoco.MjData(self.model)
        self.data.qfrc_applied[:] = built.loads.qfrc
        self.data.xfrc_applied[:] = built.loads.xfrc
        self.stages = STAGES[params["integrator"]]
        self.states: list[BodyStates] = []
        self.wall, self.done = 0.0, 0

    def run(self, times: np.ndarray, steps: np.ndarray, n_steps: int) -> Trajectory:
        """Step through every sample, then on to ``n_steps``; failures become a status."""
        try:
            previous = _start(self.built, self.model, self.data,
                              initial_state(self.built.mechanism)).quaternion
            for target in (*steps, n_steps):
                bad = self._advance_to(int(target))
                if bad is not None:
                    return self._trajectory(times, "diverged", "MuJoCo raised a bad qpos/qvel/"
                                            "qacc warning (it would reset and carry on)",
                                            bad * self.dt)
                if len(self.states) < len(steps):
                    self.states.append(_body_states(self.built, self.model, self.data, previous))
                    previous = self.states[-1].quaternion
        except Exception as error:  # an engine failure is a result, not a crash (DESIGN rule 5)
            return self._trajectory(times, "failed", f"{type(error).__name__}: {error}",
                                    self.done * self.dt)
        return self._trajectory(times, "ok", "", None)

    def _advance_to(self, target: int) -> int | None:
        """Step until ``target`` steps are done; the global index of a diverged step, else None."""
        count = target - self.done
        if count <= 0:
            return None
        start = time.perf_counter()
        bad = _advance(self.model, self.data, self.built.loads, count)
        self.wall += time.perf_counter() - start
        if bad is not None:
            self.done += bad
            return self.done
        self.done = target
        return None

    def _trajectory(self, times, status: str, reason: str, failure_time) -> Trajectory:
        kwargs = dict(status=status, reason=reason, failure_time=failure_time,
                      wall_time_s=self.wall, steps=self.done,
                      counters={"rhs_evals": self.done * self.stages},
                      notes=_notes(self.built, self.model))
        if not self.states:
            return Trajectory.empty(len(self.built.mechanism.bodies), **kwargs)
        return Trajectory.from_samples(times, self.states, **kwargs)


def export_mjcf(mech: Mechanism) -> str:
    """The MJCF text of the model :meth:`MujocoAdapter.build` makes for ``mech``.

    Raises
    ------
    UnsupportedCase
        When MuJoCo cannot represent ``mech``.
    """
    return MujocoAdapter().build(mech).spec.to_xml()
