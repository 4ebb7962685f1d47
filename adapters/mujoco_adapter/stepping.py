"""Stepping a MuJoCo model: chunks of steps inside MuJoCo, pose-dependent loads refreshed before
every step, and MuJoCo's bad-qpos/qvel/qacc warnings turned into the index of the step that
diverged.
"""

from __future__ import annotations

import functools
from collections.abc import Callable

import mujoco
import numpy as np

from mbh._adapters.mujoco_adapter.loads import _Loads, _moving_wrenches

#: Warnings that mean the state went bad (MuJoCo then resets the simulation and carries on):
#: bad qpos, bad qvel, bad qacc, consecutive in ``mjtWarning``, so one slice of the counters.
DIVERGENCE_WARNINGS = slice(int(mujoco.mjtWarning.mjWARN_BADQPOS),
                            int(mujoco.mjtWarning.mjWARN_BADQACC) + 1)
#: The part of the state a run is replayed from (time, qpos, qvel, warm start, applied forces …).
_STATE = mujoco.mjtState.mjSTATE_INTEGRATION


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


def _steps_with_loads(model: mujoco.MjModel, data: mujoco.MjData, loads: _Loads,
                      count: int) -> None:
    """Take ``count`` steps one by one, refreshing the pose-dependent loads before each."""
    for _ in range(count):
        _step_once(model, data, loads)


def _steps(model: mujoco.MjModel, data: mujoco.MjData, loads: _Loads) -> Callable[[int], None]:
    """A function taking ``count`` steps with no checks: inside MuJoCo (``mj_step(nstep=count)``)
    unless pose-dependent loads must be refreshed before every step."""
    if loads.moving:
        return functools.partial(_steps_with_loads, model, data, loads)
    return functools.partial(mujoco.mj_step, model, data)


class Stepping:
    """The steps of one run and the divergence check after each chunk of them.

    A chunk runs as :attr:`run` (also the bare loop of
    :meth:`mbh._adapters.mujoco_adapter.adapter.MujocoAdapter.bare_loop`); afterwards the caller asks
    :meth:`diverged` (the counters are zeroed at the start, so any count means a divergence).
    Only when one fired is the run replayed (:meth:`first_bad_step`) — from the start state saved
    here, to the chunk's start in one call, then step by step — to find the step: MuJoCo is
    deterministic, so the replay retraces the run, and a good run pays for one counter read per
    chunk.

    Parameters
    ----------
    model, data
        The configured model and its data at the run's start state.
    loads : _Loads

    Attributes
    ----------
    run : callable
        ``run(count)`` takes ``count`` steps with no checks (:func:`_steps`).
    """

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, loads: _Loads):
        self.model, self.data, self.loads = model, data, loads
        self.run = _steps(model, data, loads)
        self._start = np.empty(mujoco.mj_stateSize(model, _STATE))
        mujoco.mj_getState(model, data, self._start, _STATE)
        _clear_warnings(data)
        self._counters = data.warning.number[DIVERGENCE_WARNINGS]  # a view: read, not copied

    def diverged(self) -> bool:
        """True when a divergence warning was raised since the counters were last zeroed."""
        return any(self._counters.tolist())

    def first_bad_step(self, taken: int, count: int) -> int | None:
        """The 1-based step of the last chunk that raised a warning, by replaying the run.

        Parameters
        ----------
        taken : int
            Steps before the chunk.
        count : int
            Steps in the chunk.
        """
        mujoco.mj_setState(self.model, self.data, self._start, _STATE)
        self.run(taken)
        _clear_warnings(self.data)
        for step in range(1, count + 1):
            _step_once(self.model, self.data, self.loads)
            if self.diverged():
                return step
        return None
