"""Stepping a MuJoCo model: chunks of steps inside MuJoCo, pose-dependent loads refreshed before
every step, and MuJoCo's bad-qpos/qvel/qacc warnings turned into the index of the step that
diverged.
"""

from __future__ import annotations

import mujoco
import numpy as np

from adapters.mujoco_adapter.loads import _Loads, _moving_wrenches

#: Warnings that mean the state went bad (MuJoCo then resets the simulation and carries on).
DIVERGENCE_WARNINGS = np.array([mujoco.mjtWarning.mjWARN_BADQPOS, mujoco.mjtWarning.mjWARN_BADQVEL,
                                mujoco.mjtWarning.mjWARN_BADQACC], dtype=int)


def _diverged(data: mujoco.MjData) -> bool:
    """True when a divergence warning was raised since :func:`_clear_warnings`."""
    return bool(data.warning.number[DIVERGENCE_WARNINGS].any())


def _clear_warnings(data: mujoco.MjData) -> None:
    """Zero the divergence warning counters.

    Comparing counts is not enough: MuJoCo's automatic reset clears the counters before it
    records the warning that caused it, so a second divergence leaves the count at 1.
    """
    data.warning.number[DIVERGENCE_WARNINGS] = 0


def _step_once(model: mujoco.MjModel, data: mujoco.MjData, loads: _Loads) -> None:
    """One step, with the pose-dependent loads refreshed first when there are any."""
    if loads.moving:
        mujoco.mj_kinematics(model, data)
        data.xfrc_applied[:] = _moving_wrenches(loads, data)
    mujoco.mj_step(model, data)


def _first_bad_step(model: mujoco.MjModel, data: mujoco.MjData, loads: _Loads,
                    count: int) -> int | None:
    """Step ``count`` times one by one; the 1-based step that raised a divergence warning."""
    _clear_warnings(data)
    for step in range(1, count + 1):
        _step_once(model, data, loads)
        if _diverged(data):
            return step
    return None


def _advance(model: mujoco.MjModel, data: mujoco.MjData, loads: _Loads, count: int) -> int | None:
    """Take ``count`` steps; the 1-based index of the step that diverged, else None.

    Without pose-dependent loads the steps run inside MuJoCo (``mj_step(nstep=count)``); if that
    raised a warning, the chunk is replayed from a saved state step by step to find which step.
    """
    if loads.moving:
        return _first_bad_step(model, data, loads, count)
    kind = mujoco.mjtState.mjSTATE_INTEGRATION
    saved = np.empty(mujoco.mj_stateSize(model, kind))
    mujoco.mj_getState(model, data, saved, kind)
    _clear_warnings(data)
    mujoco.mj_step(model, data, count)
    if not _diverged(data):
        return None
    mujoco.mj_setState(model, data, saved, kind)
    return _first_bad_step(model, data, loads, count)
