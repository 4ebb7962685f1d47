"""Body-state trajectories: what every adapter returns (docs/design.md, data flow).

All arrays are in the world frame.  Quaternions are scalar-first ``[w, x, y, z]`` and rotate body
vectors into the world (the Euler parameters θ0..θ3 of Rouvinen 2003, eq. 3).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mbh._harness.common.status import CaseStatus

#: Every case status, in the order reports list them (:class:`CaseStatus` says what each means).
STATUSES = tuple(CaseStatus)


@dataclass
class BodyStates:
    """The state of every body at one instant.

    Attributes
    ----------
    position : ndarray, shape (n_bodies, 3)
        Centre-of-mass positions, m.
    quaternion : ndarray, shape (n_bodies, 4)
        Orientations, scalar first.
    velocity : ndarray, shape (n_bodies, 3)
        Centre-of-mass velocities, m/s.
    angular_velocity : ndarray, shape (n_bodies, 3)
        Angular velocities in world axes, rad/s.
    """

    position: np.ndarray
    quaternion: np.ndarray
    velocity: np.ndarray
    angular_velocity: np.ndarray


@dataclass
class Trajectory:
    """Sampled body states plus what the run cost and how it ended.

    Attributes
    ----------
    times : ndarray, shape (n_samples,)
        Sample times reached, s.  A failed run holds the samples before the failure.
    position, quaternion, velocity, angular_velocity : ndarray, shape (n_samples, n_bodies, k)
        As in :class:`BodyStates`, one slice per sample time.
    status : CaseStatus
        How the run ended (a plain string of :class:`CaseStatus` is read as its member).
    reason : str
        Why the run did not end ``ok`` (empty otherwise).
    failure_time : float or None
        Time of the last good state (the last state the method produced that passed the
        checks) of a run that did not end ``ok``, s; None when it did.
    wall_time_s : float
        Wall time around the stepping only, s.
    read_back_s : float
        Wall time spent reading body states back at the samples, s (not in ``wall_time_s``;
        printed by ``mbh bench``, not stored).
    steps : int
        Integrator steps taken.
    counters : dict
        Cost counters: ``rhs_evals``, ``jacobian_evals``, ``factorizations``,
        ``newton_iterations`` and any engine-specific ones.
    notes : list of str
        Facts a reader of the case must know (e.g. redundant closure equations).
    """

    times: np.ndarray
    position: np.ndarray
    quaternion: np.ndarray
    velocity: np.ndarray
    angular_velocity: np.ndarray
    status: CaseStatus = CaseStatus.OK
    reason: str = ""
    failure_time: float | None = None
    wall_time_s: float = 0.0
    read_back_s: float = 0.0
    steps: int = 0
    counters: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)

    def __post_init__(self):
        if self.status not in STATUSES:
            raise ValueError(f"status must be one of {', '.join(STATUSES)}, got {self.status!r}")
        self.status = CaseStatus(self.status)

    @property
    def n_samples(self) -> int:
        return len(self.times)

    def at(self, index: int) -> BodyStates:
        """Body states at sample ``index``."""
        return BodyStates(self.position[index], self.quaternion[index], self.velocity[index],
                          self.angular_velocity[index])

    @classmethod
    def from_samples(cls, times, states: list[BodyStates], **kwargs) -> "Trajectory":
        """Stack per-sample :class:`BodyStates` (possibly fewer than ``times``: a failed run)."""
        n = len(states)
        if n == 0:
            return cls.empty(**kwargs)
        return cls(
            times=np.asarray(times[:n], dtype=float),
            position=np.stack([s.position for s in states]),
            quaternion=np.stack([s.quaternion for s in states]),
            velocity=np.stack([s.velocity for s in states]),
            angular_velocity=np.stack([s.angular_velocity for s in states]),
            **kwargs,
        )

    @classmethod
    def empty(cls, n_bodies: int = 0, **kwargs) -> "Trajectory":
        """A trajectory with no samples (an unsupported or immediately failed case)."""
        z3 = np.zeros((0, n_bodies, 3))
        return cls(times=np.zeros(0), position=z3, quaternion=np.zeros((0, n_bodies, 4)),
                   velocity=z3.copy(), angular_velocity=z3.copy(), **kwargs)
