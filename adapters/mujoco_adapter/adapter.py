"""The MuJoCo adapter: the harness's contract over :mod:`.build`, :mod:`.state`, :mod:`.methods`
and :mod:`.stepping`, the engine-specific stepper driven by the shared run loop
(:meth:`mbh._adapters.base.Adapter.simulate`), and :func:`export_mjcf`.
"""

from __future__ import annotations

import time
import xml.etree.ElementTree as ElementTree

import mujoco
import numpy as np

from mbh._adapters import closure_notes
from mbh._adapters.base import Adapter, MethodSpec, RunFailure, RunGrid, Stepper
from mbh._adapters.mujoco_adapter.build import MujocoModel, build_model
from mbh._adapters.mujoco_adapter.methods import STAGES, _check_params, _configured, _method_specs
from mbh._adapters.mujoco_adapter.state import _body_states
from mbh._adapters.mujoco_adapter.state import _start as _set_start
from mbh._adapters.mujoco_adapter.stepping import Stepping
from mbh._harness.neutral.start import initial_state
from mbh._harness.model.mechanism import Mechanism
from mbh._harness.common.status import CaseStatus
from mbh._harness.model.trajectory import BodyStates, Trajectory


#: Singular values of the equality rows' Jacobian at or below this fraction of the largest count
#: as zero (the rank behind the redundancy note; Pinocchio's adapter counts with the same cut).
RANK_RTOL = 1e-10


def _notes(built: MujocoModel, equality_jacobian: np.ndarray) -> list[str]:
    """Facts a reader of a run must know; ``equality_jacobian`` is that of the equality rows at
    the start (:func:`_equality_jacobian`), whose redundant rows are counted
    (:func:`mbh._adapters.closure_notes.redundancy_notes`)."""
    notes = list(built.notes)
    notes += closure_notes.redundancy_notes(equality_jacobian,
                                            built.tree.redundant_closure_equations, RANK_RTOL)
    if built.loads.moving:
        notes.append("pose-dependent loads (cut-joint actuation, off-centre forces) are "
                     "recomputed once per step and held constant within it")
    return notes


def _equality_jacobian(model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
    """The Jacobian (``efc_J``) of the equality rows MuJoCo builds at ``data``'s state, shape
    (rows, nv), from a scratch copy of the data so the run's own is untouched."""
    if not model.neq:
        return np.zeros((0, model.nv))
    probe = mujoco.MjData(model)
    probe.qpos[:], probe.qvel[:] = data.qpos, data.qvel
    mujoco.mj_forward(model, probe)
    rows = probe.efc_type == mujoco.mjtConstraint.mjCNSTR_EQUALITY
    if mujoco.mj_isSparse(model):
        jacobian = np.zeros((probe.nefc, model.nv))
        mujoco.mju_sparse2dense(jacobian, probe.efc_J, probe.efc_J_rownnz, probe.efc_J_rowadr,
                                probe.efc_J_colind)
    else:
        jacobian = probe.efc_J.reshape(probe.nefc, model.nv)
    return jacobian[rows]


def _softness_notes(model: mujoco.MjModel, residual: float) -> list[str]:
    """The note naming the engine's limit on a model with equality constraints: they are soft,
    and their residual, here the largest ``efc_pos`` of an equality row at the run's samples
    (m), sets the error's floor (measured: docs/measurements.md, "Engine settings on hard
    loops")."""
    if not model.neq:
        return []
    solref = ", ".join(f"{value:g}" for value in model.eq_solref[0])
    solimp = ", ".join(f"{value:g}" for value in model.eq_solimp[0])
    return [f"engine limit: soft equality constraints, solref ({solref}), solimp ({solimp}); "
            f"MuJoCo's refsafe clamps the time constant to >= 2·dt and the impedance to <= "
            f"0.9999, so the loops close only to a residual that shrinks with the time constant "
            f"squared (largest equality residual at the samples {residual:.2g} m); with the time "
            f"constant at 2·dt the error falls only as dt², whatever the integrator (docs/measurements.md, \"Engine "
            f"settings on hard loops\")"]


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

    def export(self, mechanism: Mechanism) -> str:
        """The MJCF text of ``mechanism`` (:func:`export_mjcf`)."""
        return export_mjcf(mechanism)

    def model_size(self, model: MujocoModel) -> dict:
        """``nq`` of the compiled model and its equality rows (``efc`` rows of type equality
        after one ``mj_forward``: 3 per ``connect``, 6 per ``weld``); redundant rows are the
        closure equations beyond the cut joints' class in the mechanism's dimension."""
        data = mujoco.MjData(model.model)
        mujoco.mj_forward(model.model, data)
        rows = int(np.count_nonzero(data.efc_type == mujoco.mjtConstraint.mjCNSTR_EQUALITY))
        return {"coordinates": int(model.model.nq), "constraint_equations": rows,
                "redundant_equations": model.tree.redundant_closure_equations,
                "notes": f"MuJoCo nq = {model.model.nq} (tree joints), {model.model.neq} "
                         f"equality constraint(s) with {rows} rows closing the loops"}

    def bare_loop(self, model: MujocoModel, method: str, dt: float, n_steps: int) -> float:
        """MuJoCo's own loop alone: ``n_steps`` steps in one ``mj_step(nstep=n_steps)`` call
        (a Python loop of ``mj_step`` when pose-dependent loads are refreshed every step) on the
        model and start :meth:`simulate` uses, without warning checks or state read-back."""
        spec, params = self.method_spec(method)
        self._check_params(spec, params)
        stepper = self._start(model, spec, params, RunGrid(dt, n_steps * dt, np.zeros(1), True))
        began = time.perf_counter()
        stepper.stepping.run(n_steps)
        return time.perf_counter() - began

    def _check_params(self, spec: MethodSpec, params: dict) -> None:
        _check_params(params)

    def _start(self, model: MujocoModel, spec: MethodSpec, params: dict,
               grid: RunGrid) -> "_MujocoStepper":
        return _MujocoStepper(model, params, grid)


class _MujocoStepper(Stepper):
    """One MuJoCo run: the configured model and its data at the harness's initial state.

    Samples are read after step ``round(t / dt)``, the steps between two samples taken in one
    call (:class:`~mbh._adapters.mujoco_adapter.stepping.Stepping`); a bad-qpos/qvel/qacc warning ends
    the run as ``diverged`` with the state before the step that raised it as the last good one
    (MuJoCo itself would reset and carry on).
    """

    def __init__(self, built: MujocoModel, params: dict, grid: RunGrid):
        super().__init__()
        self.built, self.grid = built, grid
        self.model = _configured(built.model, params, grid.dt)
        self.data = mujoco.MjData(self.model)
        self.data.qfrc_applied[:] = built.loads.qfrc
        self.data.xfrc_applied[:] = built.loads.xfrc
        self.stages = STAGES[params["integrator"]]
        self._previous = _set_start(built, self.model, self.data,
                                    initial_state(built.mechanism)).quaternion
        self.notes = _notes(built, _equality_jacobian(self.model, self.data))
        self.stepping = Stepping(self.model, self.data, built.loads)
        self._residual = 0.0  # the largest equality residual at the samples, m

    def run(self, grid: RunGrid, n_bodies: int) -> Trajectory:
        """The shared run loop, then the note on the soft equality constraints with the largest
        residual the run's samples met (:func:`_softness_notes`)."""
        trajectory = super().run(grid, n_bodies)
        trajectory.notes.extend(_softness_notes(self.model, self._residual))
        return trajectory

    def _step_to(self, t: float) -> None:
        count = self.grid.steps(t) - self.steps
        if count <= 0:
            return
        self.stepping.run(count)
        if self.stepping.diverged():
            self._diverged(count)
        self.steps += count
        self.t_good = self.steps * self.grid.dt

    def _diverged(self, count: int) -> None:
        """End the run at the step of the last ``count`` that raised a warning."""
        bad = self.stepping.first_bad_step(self.steps, count)
        if bad is None:
            raise RuntimeError("MuJoCo raised a divergence warning that a replay of the run did "
                               "not reproduce")
        self.steps += bad
        self.t_good = (self.steps - 1) * self.grid.dt
        raise RunFailure(CaseStatus.DIVERGED, "MuJoCo raised a bad qpos/qvel/qacc warning (it "
                                               "would reset and carry on)")

    def _states(self, t: float) -> BodyStates:
        data = self.data
        if self.model.neq and data.nefc:
            rows = data.efc_type == mujoco.mjtConstraint.mjCNSTR_EQUALITY
            if rows.any():
                self._residual = max(self._residual, float(np.abs(data.efc_pos[rows]).max()))
        states = _body_states(self.built, self.model, data, self._previous)
        self._previous = states.quaternion
        return states

    def counters(self) -> dict:
        return {"rhs_evals": self.steps * self.stages}


def export_mjcf(mech: Mechanism) -> str:
    """The MJCF text of the model :meth:`MujocoAdapter.build` makes for ``mech``, every body's
    mass properties written at full precision (:func:`_with_exact_inertials`).

    Raises
    ------
    UnsupportedCase
        When MuJoCo cannot represent ``mech``.
    """
    built = MujocoAdapter().build(mech)
    return _with_exact_inertials(built.spec.to_xml(), built.model)


def _exact(values) -> str:
    """``values`` as MJCF text that reads back to the same doubles (shortest round trip)."""
    return " ".join(repr(float(value)) for value in np.atleast_1d(values))


def _with_exact_inertials(text: str, model: mujoco.MjModel) -> str:
    """``text`` (MJCF) with each body's ``<inertial>`` rewritten from the compiled ``model``.

    MuJoCo's writer keeps 6 significant digits: every mass property moved by up to 5e-7
    relative, and a flat body (principal moments A + B = C, raised by ~1e-9 relative for MuJoCo's
    A + B ≥ C check, :func:`~mbh._adapters.mujoco_adapter.build.balanced_inertia`) could read back
    as A + B < C and be refused.
    """
    root = ElementTree.fromstring(text)
    for body in root.iter("body"):
        inertial = body.find("inertial")
        if inertial is None:
            continue
        index = model.body(body.get("name")).id
        inertial.set("pos", _exact(model.body_ipos[index]))
        inertial.set("quat", _exact(model.body_iquat[index]))
        inertial.set("mass", _exact(model.body_mass[index]))
        inertial.set("diaginertia", _exact(model.body_inertia[index]))
    ElementTree.indent(root, space="  ")
    return ElementTree.tostring(root, encoding="unicode") + "\n"
