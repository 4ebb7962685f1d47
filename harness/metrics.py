"""One measuring stick for every adapter (DESIGN.md rule 2): errors against the reference,
constraint violations through the neutral model's own joint equations, and the energy balance,
all computed from the body states a Trajectory reports.
"""

from __future__ import annotations

import numpy as np

from adapters.inhouse.constraints import ConstraintSystem
from adapters.inhouse.states import coordinates
from harness.energy import energy_balance, kinetic_energy, state_arrays
from harness.model import Mechanism
from harness.outputs import output_series
from harness.trajectory import Trajectory

#: Sample times within this of a reference grid point match it, s.
TIME_MATCH = 1e-9


def reference_indices(reference: Trajectory, times: np.ndarray) -> np.ndarray:
    """Indices of ``times`` in the reference grid; a time off the grid raises ValueError."""
    index = np.clip(np.searchsorted(reference.times, times - TIME_MATCH), 0, reference.n_samples - 1)
    off = np.abs(reference.times[index] - times) > TIME_MATCH
    if np.any(off):
        raise ValueError(f"sample time {times[off][0]:.9g} s is not on the reference grid "
                         f"(step {reference.times[1] - reference.times[0]:g} s)")
    return index


def constraint_violations(mech: Mechanism, trajectory: Trajectory) -> dict:
    """Position- and velocity-level violation of the joint equations at every sample.

    Returns max and mean |Φ| (m or dimensionless, as the equations are written), max |Φ_q q̇|,
    the largest distance between coincident joint points (m) and, for planar mechanisms, the
    largest departure from the plane (m).
    """
    system = ConstraintSystem(mech)
    rows = np.arange(system.n_joint_equations)  # joint equations only, not θᵀθ = 1
    gap_rows = [i for i, label in enumerate(system.labels) if ": point" in label]
    position, velocity, gaps = [], [], []
    for index in range(trajectory.n_samples):
        q, v = coordinates(system.layout, trajectory.at(index))
        phi = system.phi(q)
        position.append(np.abs(phi[rows]))
        velocity.append(np.abs(system.jacobian(q)[rows] @ v))
        gaps.append(_point_gaps(phi, gap_rows, 2 if mech.planar else 3))
    position = np.array(position) if position else np.zeros((0, rows.size))
    result = {
        "max_constraint_violation": float(position.max()) if position.size else float("nan"),
        "mean_constraint_violation": float(position.mean()) if position.size else float("nan"),
        "max_velocity_violation": float(np.max(velocity)) if velocity else float("nan"),
        "max_joint_gap_m": float(np.max(gaps)) if gaps and np.size(gaps) else 0.0,
    }
    if mech.planar and trajectory.n_samples:
        result["max_out_of_plane_m"] = float(np.abs(trajectory.position[..., 2]).max())
    return result


def _point_gaps(phi: np.ndarray, gap_rows: list[int], dim: int) -> float:
    """Largest norm of the point-coincidence residual blocks (rows come in groups of dim)."""
    if not gap_rows:
        return 0.0
    blocks = phi[gap_rows].reshape(-1, dim)
    return float(np.linalg.norm(blocks, axis=1).max())


def case_metrics(mech: Mechanism, trajectory: Trajectory, reference: Trajectory | None) -> dict:
    """Every number reported for one case.

    Output errors are max |y − y_ref| over the samples reached (rad, rad/s or m); energy errors in
    J and relative to the reference's largest kinetic energy.
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
    balance = energy_balance(mech, trajectory)
    metrics["max_energy_error_J"] = float(np.abs(balance).max())
    if reference is not None:
        ref_state = state_arrays(reference)
        scale = float(kinetic_energy(mech, ref_state["velocity"], ref_state["angular_velocity"],
                                     ref_state["rotation"]).max())
        metrics["max_energy_error_rel"] = metrics["max_energy_error_J"] / scale
        index = reference_indices(reference, trajectory.times)
        metrics["output_errors"] = {
            o.name: float(np.abs(output_series(mech, trajectory, o.name)
                                 - output_series(mech, reference, o.name)[index]).max())
            for o in mech.outputs}
    return metrics
