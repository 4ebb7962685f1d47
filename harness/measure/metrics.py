"""One measuring stick for every adapter (docs/design.md, rule 2): errors against the reference,
constraint violations through the neutral model's own joint equations, and the energy balance,
all computed from the body states a Trajectory reports.
"""

from __future__ import annotations

import numpy as np

from mbh._harness.measure.energy import energy_balance, energy_scale
from mbh._harness.measure.per_reference import per_reference, read_only
from mbh._harness.neutral.equations import JointEquations
from mbh._harness.model.mechanism import GROUND, Mechanism
from mbh._harness.model.outputs import output_series
from mbh._harness.model.timegrid import reference_indices
from mbh._harness.model.trajectory import Trajectory


def lever_length(mech: Mechanism) -> float:
    """ℓ, m: the largest distance from a body's centre of mass to one of its joint points (1 m if
    every joint point sits at a centre of mass).  An orientation error of θ rad at a joint moves
    that joint's points by up to ~θ·ℓ."""
    arms = [np.linalg.norm(point) for joint in mech.joints
            for body, point in ((joint.body1, joint.point1), (joint.body2, joint.point2))
            if body != GROUND]
    return max(arms, default=0.0) or 1.0


def violation_series(mech: Mechanism, trajectory: Trajectory) -> dict:
    """Per-sample violation of the neutral joint equations (:mod:`mbh._harness.neutral.equations`).

    Returns
    -------
    dict of ndarray, each shape (n_samples,)
        ``joint_gap_m``: the largest distance between joint points that should coincide or of a
        point from its slide line, m; ``orientation_rad``: the largest orientation residual
        (axis tilt, twist, cross-axis or relative-angle error), rad; ``velocity_m_s`` and
        ``angular_velocity_rad_s``: the largest rate of those (norm over a joint's rows).  Planar
        mechanisms add, maximised over bodies: ``out_of_plane_m`` (|z|), ``tilt_rad`` (body z
        against world z), ``out_of_plane_velocity_m_s`` (|v_z|) and
        ``out_of_plane_angular_velocity_rad_s`` (|(ω_x, ω_y)|).  Non-finite states give NaN.
    """
    keys = ["joint_gap_m", "orientation_rad", "velocity_m_s", "angular_velocity_rad_s"]
    if mech.planar:
        keys += ["out_of_plane_m", "tilt_rad", "out_of_plane_velocity_m_s",
                 "out_of_plane_angular_velocity_rad_s"]
    if trajectory.n_samples == 0:
        return {key: np.zeros(0) for key in keys}
    states = (trajectory.position, trajectory.quaternion, trajectory.velocity,
              trajectory.angular_velocity)
    groups = JointEquations(mech).group_magnitudes(*states)
    series = {"joint_gap_m": groups["gap_m"], "orientation_rad": groups["orientation_rad"],
              "velocity_m_s": groups["velocity_m_s"],
              "angular_velocity_rad_s": groups["angular_velocity_rad_s"]}
    if mech.planar:
        series |= JointEquations.plane_residuals(*states)
    return {key: np.max(value, axis=-1, initial=0.0) for key, value in series.items()}


def constraint_violations(mech: Mechanism, trajectory: Trajectory) -> dict:
    """Largest and mean violations of the joint equations over the samples, one unit per key.

    ``max_joint_gap_m``/``mean_joint_gap_m`` (m), ``max_orientation_violation_rad``/
    ``mean_orientation_violation_rad`` (rad), ``max_velocity_violation_m_s``,
    ``max_angular_velocity_violation_rad_s`` and for planar mechanisms ``max_out_of_plane_m``,
    ``max_tilt_rad``, ``max_out_of_plane_velocity_m_s``, ``max_out_of_plane_angular_velocity_rad_s``
    (see :func:`violation_series`).  ``max_constraint_violation``/``mean_constraint_violation`` (m)
    condense the position level into one length: per sample the larger of the joint gap and the
    orientation residual times the lever length ℓ (:func:`lever_length`); ``max_velocity_violation``
    (m/s) likewise.  Means are over samples of the per-sample maxima; NaN without samples.
    """
    series = violation_series(mech, trajectory)
    lever = lever_length(mech)
    length = np.maximum(series["joint_gap_m"], lever * series["orientation_rad"])
    speed = np.maximum(series["velocity_m_s"], lever * series["angular_velocity_rad_s"])
    empty = trajectory.n_samples == 0

    def reduce(values, how):
        return float("nan") if empty else float(how(values))

    result = {
        "max_constraint_violation": reduce(length, np.max),
        "mean_constraint_violation": reduce(length, np.mean),
        "max_velocity_violation": reduce(speed, np.max),
        "max_joint_gap_m": reduce(series["joint_gap_m"], np.max),
        "mean_joint_gap_m": reduce(series["joint_gap_m"], np.mean),
        "max_orientation_violation_rad": reduce(series["orientation_rad"], np.max),
        "mean_orientation_violation_rad": reduce(series["orientation_rad"], np.mean),
        "max_velocity_violation_m_s": reduce(series["velocity_m_s"], np.max),
        "max_angular_velocity_violation_rad_s": reduce(series["angular_velocity_rad_s"], np.max),
    }
    plane = ("out_of_plane_m", "tilt_rad", "out_of_plane_velocity_m_s",
             "out_of_plane_angular_velocity_rad_s")
    return result | {f"max_{key}": reduce(series[key], np.max) for key in plane if key in series}


def case_metrics(mech: Mechanism, trajectory: Trajectory, reference: Trajectory | None) -> dict:
    """Every number reported for one case.

    Output errors are max |y − y_ref| over the samples reached (rad, rad/s or m); sample times
    must lie on the reference grid (ValueError otherwise).  The energy-balance error is in J and
    relative to :func:`mbh._harness.measure.energy.energy_scale` of the reference (the most energy that moves
    through it: kinetic, potential range or applied work; M·|g|·ℓ for a reference at rest;
    ``None`` when neither exists); with a reference the work of
    dampers and spatial world torques uses the reference as a control variate
    (:func:`mbh._harness.measure.energy.energy_balance`).
    """
    metrics = {
        "status": trajectory.status, "reason": trajectory.reason,
        "failure_time": trajectory.failure_time, "wall_time_s": trajectory.wall_time_s,
        "steps": trajectory.steps, "rhs_evals": trajectory.counters.get("rhs_evals"),
        "counters": dict(trajectory.counters), "notes": list(trajectory.notes),
        "samples": trajectory.n_samples,
    }
    if trajectory.n_samples == 0:
        return metrics
    metrics["final_time"] = float(trajectory.times[-1])
    metrics["outputs"] = {o.name: float(output_series(mech, trajectory, o.name)[-1])
                          for o in mech.outputs}
    metrics.update(constraint_violations(mech, trajectory))
    balance = energy_balance(mech, trajectory, reference)
    metrics["max_energy_error_J"] = float(np.abs(balance).max())
    if reference is not None:
        scale = energy_scale(mech, reference)
        metrics["max_energy_error_rel"] = (None if scale is None
                                           else metrics["max_energy_error_J"] / scale)
        index = reference_indices(reference, trajectory.times)
        expected = reference_outputs(mech, reference)
        metrics["output_errors"] = {
            o.name: float(np.abs(output_series(mech, trajectory, o.name)
                                 - expected[o.name][index]).max())
            for o in mech.outputs}
    return metrics


@per_reference
def reference_outputs(mech: Mechanism, reference: Trajectory) -> dict[str, np.ndarray]:
    """Every output of ``mech`` along ``reference`` (:func:`output_series`), by name, each shape
    (n_samples,), read-only: what :func:`case_metrics` compares a run's outputs with."""
    return {o.name: read_only(output_series(mech, reference, o.name)) for o in mech.outputs}
