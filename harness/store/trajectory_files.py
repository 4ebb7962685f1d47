"""A case's trajectory as a file of the run folder: ``trajectories/<case>.npz`` holds the body
states (:data:`ARRAYS`) and a JSON string of everything else (status, reason, failure time,
cost counters, notes).
"""

from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path

import numpy as np

from mbh._harness.model.trajectory import Trajectory
from mbh._harness.store.files import write_arrays

__all__ = ["ARRAYS", "save_trajectory", "load_trajectory", "trajectory_name"]

#: The trajectory's arrays stored as they are (float).
ARRAYS = ("times", "position", "quaternion", "velocity", "angular_velocity")


def _json_default(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"cannot store a {type(value).__name__} in a trajectory: {value!r}")


def save_trajectory(path: Path, trajectory: Trajectory) -> None:
    """``trajectory`` as an npz: its arrays plus a JSON string of everything else."""
    meta = {"status": trajectory.status, "reason": trajectory.reason,
            "failure_time": trajectory.failure_time, "wall_time_s": trajectory.wall_time_s,
            "steps": trajectory.steps, "counters": trajectory.counters,
            "notes": trajectory.notes}
    arrays = {name: np.asarray(getattr(trajectory, name), dtype=float) for name in ARRAYS}
    arrays["meta"] = np.array(json.dumps(meta, default=_json_default))
    path.parent.mkdir(parents=True, exist_ok=True)
    write_arrays(path, arrays)


def load_trajectory(path: Path) -> Trajectory:
    """The trajectory :func:`save_trajectory` wrote in ``path``.

    Raises
    ------
    OSError, ValueError, KeyError, TypeError, EOFError, zipfile.BadZipFile
        When the file is damaged (:data:`mbh._harness.store.problems.DAMAGE`).
    """
    with np.load(path, allow_pickle=False) as data:
        arrays = {name: data[name] for name in ARRAYS}
        meta = json.loads(str(data["meta"]))
    return Trajectory(**arrays, **meta)


def trajectory_name(case_id: str) -> str:
    """A file name for ``case_id``: readable part plus a hash (unique, filesystem-safe)."""
    readable = re.sub(r"[^A-Za-z0-9._=-]+", "_", case_id)[:100]
    return f"{readable}-{hashlib.sha256(case_id.encode()).hexdigest()[:12]}.npz"
