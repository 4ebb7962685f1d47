"""Passing a singular position with a placed step: no stage of a fixed-step method lands next to it.

At a singular position (a fold or branch crossing of the constraint set: σ_min of Φ_q → 0) the
index-1 acceleration (Rouvinen 2003, eq. 77) divides the stage state's small inconsistencies by σ_min: a
stage that lands at a distance ψ from the crossing gets an acceleration error ~ ε/ψ, ε the
state's constraint residual there.  With a fixed step the stages land wherever the grid puts them,
and the smaller the step, the closer the closest one comes: on the plain grid the error can grow
as the step shrinks (figures in docs/measurements.md).

So the step that passes a singular position is placed: the passage is predicted from the
conditioning indicator ρ̂ (:func:`~mbh._adapters.inhouse.numerics.banded.conditioning_indicator`, ≈ σ_min/σ_max
of Φ_q, linear in the distance to the crossing) at the last two step ends, and the run takes

1. a *lead* step up to where the passage lies at the fraction c* of the next step, c* the middle
   of the widest gap g between the tableau's stage times (and 1): 1/4 for rk4 (g = 1/2), 0.47
   for rk8 (g = 0.27);
2. the *passage* step of length H = max(dt, :data:`SAFE_INDICATOR` / (g/2 · |dρ̂/dt|)), so that
   its stages stay at least a ρ̂-distance SAFE_INDICATOR from the crossing;
3. a *closing* step back onto the run's grid t0 + k·dt,

each a step of the method followed by the formulation's projection.  The three replace the grid
steps they cover; a passage that would cover a sample time is shortened to end there (or, with
no room for half a step, not placed).  The state is read only at grid times, so the samples are
those of a run on the grid.  Used by the ``none``, ``baumgarte``, ``direct`` and ``partition``
strategies with the fixed-step one-step methods, on both stepping paths (the same plan from the
same numbers, so the same steps); ``passage=0`` turns it off.  Coordinate partitioning measures ρ̂
in its re-partition check after each step and keeps its stages farther away (its own clearance,
:attr:`~mbh._adapters.inhouse.formulations.partition.CoordinatePartitioning.passage_clearance`).

With placed passages ``best`` converges through the passages of double_fourbar as the step
shrinks, down to a floor set by the unstable motion between passages, not by the passages; the
cost is a few per cent per step (the indicator, one Cholesky factorisation of Φ_q Φ_qᵀ, banded
from :data:`~mbh._adapters.inhouse.numerics.banded.BANDED_MIN_ROWS` rows, and for ``none`` and ``baumgarte`` the
Φ_q it needs).  Errors and timings, placed against the plain grid, with the commands that
reproduce them: docs/measurements.md, "Placed steps through singular positions".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

#: A passage is planned only where ρ̂ has fallen below this fraction of its value at the start
#: (a crossing, not the ordinary rise and fall of the conditioning along a motion).
FOLD_ZONE = 0.1
#: The ρ̂-distance from the crossing that the passage step keeps its stages at.  Chosen on
#: parallelogram_fourbar and double_fourbar against 3e-5 and 1e-5 (docs/measurements.md).
SAFE_INDICATOR = 1e-4


def passage_placement(c: np.ndarray, clearance: float = SAFE_INDICATOR) -> np.ndarray:
    """(c*, g/2, clearance): the middle of the widest gap g between the sorted distinct stage
    times c (s,) and 1 (the first widest one) and the distance from it to the nearest stage time,
    as fractions of the step, and the ρ̂-distance the passage keeps its stages at; shape (3,)."""
    times = np.unique(np.append(np.asarray(c, dtype=float), [0.0, 1.0]))
    gaps = np.diff(times)
    widest = int(np.argmax(gaps))
    return np.array([times[widest] + gaps[widest] / 2, gaps[widest] / 2, clearance])


@njit(cache=True)
def plan_passage(t, dt, t_last, rho, rho_previous, rho_zone, placement):
    """The lead and passage step lengths (s) when the next grid step should be replaced by a
    placed passage, else (0, 0).

    Parameters
    ----------
    t : float
        Time of the current grid point, s.
    dt : float
        The run's step, s.
    t_last : float
        The grid time the run must stop at next (a sample), s; the passage ends by then.
    rho, rho_previous : float
        ρ̂ at t and at the grid point before.
    rho_zone : float
        :data:`FOLD_ZONE` × ρ̂ at the start.
    placement : ndarray, shape (3,)
        (c*, g/2) of the tableau and the clearance (:func:`passage_placement`).
    """
    fraction, half_gap, clearance = placement[0], placement[1], placement[2]
    if not (0.0 < rho < rho_previous and rho < rho_zone):
        return 0.0, 0.0
    rate = (rho_previous - rho) / dt
    lead_time = rho / rate
    length = max(dt, clearance / (half_gap * rate))
    if lead_time > fraction * length + dt:
        return 0.0, 0.0  # the crossing is more than a step beyond the passage's start
    if lead_time < fraction * length:  # too close to centre a full passage: a shorter one
        length = lead_time / fraction
    lead = lead_time - fraction * length
    room = t_last - t - lead_time  # from the crossing to the next sample
    if lead_time + (1.0 - fraction) * length > t_last - t:
        length = room / (1.0 - fraction)
        lead = lead_time - fraction * length
    if length < 0.5 * dt:
        return 0.0, 0.0  # no room for a passage that helps: an ordinary step
    return lead, length


@njit(cache=True)
def passage_times(t0, dt, k, lead, length):
    """End times of the placed steps from grid point k (t = t0 + k·dt): the lead step (when
    ``lead`` > 0), the passage, and the closing step onto the grid point k_end, the first at or
    after the passage's end (a passage ending within 1e-6·dt of a grid point is stretched to it).

    Returns
    -------
    ends : ndarray, shape (1,) to (3,)
        Increasing end times, s; the last is t0 + k_end·dt.  A lead of at most 1e-6·dt is
        left out (the passage then starts at t).
    k_end : int
    """
    t = t0 + k * dt
    passage_end = t + lead + length
    k_end = int(np.ceil((passage_end - t0) / dt - 1e-6))
    t_grid = t0 + k_end * dt
    ends = np.empty(3)
    count = 0
    if lead > 1e-6 * dt:
        ends[count] = t + lead
        count += 1
    if t_grid - passage_end > 1e-6 * dt:
        ends[count] = passage_end
        count += 1
    ends[count] = t_grid
    return ends[:count + 1], k_end


@dataclass(frozen=True)
class Passages:
    """The placed passages of one fixed-step run, shared by both stepping paths.

    Attributes
    ----------
    placement : ndarray, shape (3,)
        (c*, g/2) of the method's tableau and the formulation's clearance
        (:func:`passage_placement`); zeros when no passage is placed.
    rho_zone : float
        :data:`FOLD_ZONE` × ρ̂ at the start.
    indicators : ndarray, shape (2,)
        The formulation's ρ̂ at its last two step ends (updated as it measures them).
    count : ndarray of int64, shape (1,)
        Passages placed so far.
    """

    placement: np.ndarray
    rho_zone: float
    indicators: np.ndarray
    count: np.ndarray

    @classmethod
    def of(cls, formulation, integrator_class) -> Passages:
        """The passages of ``formulation`` (those whose strategy keeps ``indicators``)
        integrated by ``integrator_class``, placed only for one-step methods with a tableau; for
        other methods the formulation stops measuring ρ̂ (its ``indicators`` become None)."""
        indicators = formulation.indicators
        tableau = getattr(integrator_class, "tableau", None)
        if tableau is None:
            formulation.indicators = None
        if indicators is None or tableau is None:
            return cls(np.zeros(3), 0.0, np.zeros(2), np.zeros(1, dtype=np.int64))
        return cls(passage_placement(tableau.c, formulation.passage_clearance),
                   FOLD_ZONE * float(indicators[0]), indicators, np.zeros(1, dtype=np.int64))

    @property
    def arrays(self) -> tuple:
        """(placement, rho_zone, indicators, count), as :func:`mbh._adapters.inhouse.stepping.compiled.
        run_samples` takes them."""
        return self.placement, self.rho_zone, self.indicators, self.count

    def plan(self, k: int, dt: float, last: int):
        """The placed steps from grid step ``k`` (:func:`plan_passage`, :func:`passage_times`
        on the grid t = k·dt ending by step ``last``): (end times (s), grid steps covered), or
        None for an ordinary step."""
        if not self.placement[0] > 0.0:
            return None
        lead, length = plan_passage(k * dt, dt, last * dt, self.indicators[1],
                                    self.indicators[0], self.rho_zone, self.placement)
        if not length > 0.0:
            return None
        ends, k_end = passage_times(0.0, dt, k, lead, length)
        return ends, k_end - k
