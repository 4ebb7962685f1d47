"""The adapter contract every engine implements, the in-house formulation included.

``build(mechanism)`` → engine model; ``simulate(model, method, dt, t_end, sample_times)`` →
:class:`~mbh._harness.model.trajectory.Trajectory`; ``methods()`` lists the engine's methods with their
parameters; ``version()`` names the engine version.  Method names are user-facing strings
``NAME[:key=value,...]`` parsed by :func:`parse_method`.

One run loop
------------
:meth:`Adapter.simulate` is a template shared by every adapter.  It resolves the method, checks
the times with one rule (:func:`check_run_times`), asks the adapter for an engine-specific
:class:`Stepper` (``Adapter._start``), steps it through every sample time and on to ``t_end``,
checks every state it reads (:func:`divergence_reason`) and turns every way a run can end into a
status (:class:`~mbh._harness.common.status.CaseStatus`):

* ``ok``: every state read was finite and within :data:`DIVERGENCE_LIMIT`;
* ``diverged``: a state read was non-finite or beyond the limit, or the engine's own divergence
  check fired (:class:`RunFailure` with status ``diverged``);
* ``failed``: the method stopped — a solver failure reported through :class:`RunFailure`, or any
  exception raised by the adapter or the engine during the run (reason
  ``"<ExceptionType>: message"``);
* ``unsupported``: ``_start`` raised :class:`UnsupportedCase`.

A stepper that breaks the contract — :meth:`Stepper._states` returns anything but
:class:`~mbh._harness.model.trajectory.BodyStates` of arrays shaped (n_bodies, 3) and (n_bodies, 4) —
ends the run ``failed`` with the shape it gave.  The reason of a run that a third-party adapter's
own code ended (an exception, a broken contract) names the adapter, its package and the stage
(:func:`blame`), so a campaign's row points at the package to fix.

``failure_time`` is the time of the last good state: the last state the method produced that
passed the checks (the stepper's own per-step checks where it has them, :attr:`Stepper.t_good`,
else the last state this loop read and checked).  Every sample before it is kept.  A failure
before the engine holds its start state gives no samples and ``failure_time`` 0.0.  Wall time is
measured around the stepping only (``Stepper._step_to``); the time spent reading states back
(``Stepper._states``) is ``Trajectory.read_back_s``.
"""

from __future__ import annotations

import abc
import math
import time
from dataclasses import dataclass, field

import numpy as np

from mbh._harness.model.mechanism import Mechanism
from mbh._harness.common.status import CaseStatus
from mbh._harness.model.trajectory import BodyStates, Trajectory

#: A body whose position (m), velocity (m/s) or angular velocity (rad/s) exceeds this in norm has
#: diverged (the same limit as the integrators' default ``divergence_limit``).
DIVERGENCE_LIMIT = 1e8
#: Relative tolerance of "an integer multiple of dt" (t_end, and sample times of fixed-step
#: methods): |t − k·dt| ≤ GRID_RTOL · max(t, dt).
GRID_RTOL = 1e-9
#: The closure contract of the joint-coordinate engines (MuJoCo, Bullet, Pinocchio): each builder
#: has ``closure_equations(mech: Mechanism, joint: Joint) -> int``, the number of constraint
#: equations the engine closes a loop cut at ``joint`` with, or this value when it cannot close
#: that joint at all; it is large, so a spanning tree
#: (:func:`mbh._harness.model.topology.spanning_tree`) cuts such a joint only when it must.
UNCLOSABLE = 1000


def steps_in(dt: float, t_end: float) -> int:
    """Number of steps of size ``dt`` (s, > 0) that make the duration ``t_end`` (s).

    Raises
    ------
    ValueError
        When ``t_end`` is not an integer multiple of ``dt`` (to :data:`GRID_RTOL`), or holds more
        steps than a double counts; the message names both.
    """
    ratio = t_end / dt
    if not math.isfinite(ratio):  # a step near the double's smallest
        raise ValueError(f"step {dt!r} s is too small: the duration {t_end!r} s holds more steps "
                         f"than a double counts")
    count = round(ratio)
    if count < 1 or abs(t_end - count * dt) > GRID_RTOL * max(t_end, dt):
        raise ValueError(f"step {dt!r} s does not divide the duration {t_end!r} s: t_end must be "
                         f"an integer multiple of dt")
    return count


class UnsupportedCase(Exception):
    """Raised by ``build`` (or ``_start``) when the engine cannot represent the mechanism or the
    method; the message says why."""


class RunFailure(Exception):
    """Raised by a :class:`Stepper` when the engine stopped the run.

    Parameters
    ----------
    status : {"failed", "diverged"}
        The run's :class:`~mbh._harness.common.status.CaseStatus` (a member or its string, such
        as an in-house integrator's state once it stopped).
    reason : str
        What happened, for the trajectory's ``reason``.
    """

    def __init__(self, status: str, reason: str):
        if status not in (CaseStatus.FAILED, CaseStatus.DIVERGED):
            raise ValueError(f"RunFailure status must be 'failed' or 'diverged', got {status!r}")
        super().__init__(reason)
        self.status = CaseStatus(status)
        self.reason = reason


def describe(error: BaseException) -> str:
    """``"<ExceptionType>: message"`` on one line (the reason of a run ended by an exception)."""
    return f"{type(error).__name__}: {' '.join(str(error).split())}"


def adapter_label(name: str, package: str) -> str:
    """``adapter 'toy' from package mbh-toy-adapter 0.1.0``, or ``adapter 'mujoco' (built-in)``
    for an empty ``package`` (``"NAME VERSION"`` of the distribution providing the adapter)."""
    return f"adapter {name!r} " + (f"from package {package}" if package else "(built-in)")


def blame(source: str, stage: str, error: BaseException | str) -> str:
    """The reason of a run that an adapter's own code ended in ``stage`` (``build``, ``_start``,
    ``the run``): an exception (``describe(error)``) or a broken contract (a message).

    With a ``source`` (:attr:`Adapter.source`: a third-party adapter) the reason names it:
    ``"adapter 'toy' from package mbh-toy-adapter 0.1.0, in build: ZeroDivisionError: division
    by zero"``; a built-in adapter's reason is the bare text.
    """
    text = describe(error) if isinstance(error, BaseException) else error
    return f"{source}, in {stage}: {text}" if source else text


#: The arrays of :class:`BodyStates` and the width of each, (n_bodies, width).
_STATE_WIDTHS = {"position": 3, "quaternion": 4, "velocity": 3, "angular_velocity": 3}


def malformed(states, n_bodies: int) -> str | None:
    """How ``states`` breaks the contract of :meth:`Stepper._states` (a :class:`BodyStates`
    whose arrays have shapes (n_bodies, 3) and, for the quaternion, (n_bodies, 4)), or None."""
    if not isinstance(states, BodyStates):
        return f"returned {type(states).__name__}, not BodyStates"
    for name, width in _STATE_WIDTHS.items():
        shape = np.shape(getattr(states, name))
        if shape != (n_bodies, width):
            return f"returned {name} of shape {shape}, expected {(n_bodies, width)}"
    return None


def _bad(name: str, value, rule: str) -> ValueError:
    return ValueError(f"invalid {name} = {value!r}: {rule}")


def check_run_times(dt, t_end, sample_times, fixed_step: bool = True) -> np.ndarray:
    """Check the times of a run with the one rule every adapter shares.

    Rule: ``dt`` and ``t_end`` finite and > 0; ``t_end`` an integer multiple of ``dt`` within the
    relative :data:`GRID_RTOL`; ``sample_times`` a 1-D array of finite, strictly increasing times
    in [0, t_end] (t_end itself within GRID_RTOL), on the step grid (integer multiples of ``dt``
    within GRID_RTOL) when the method takes fixed steps.

    Parameters
    ----------
    dt : float
        Step size (first-step hint of an adaptive method), s.
    t_end : float
        End time, s.
    sample_times : array_like, shape (k,)
        s.
    fixed_step : bool
        Whether the method takes steps of exactly ``dt``.

    Returns
    -------
    ndarray, shape (k,)
        ``sample_times`` as floats.

    Raises
    ------
    ValueError
        ``"invalid <argument> = <value>: <rule>"`` for the first argument that breaks the rule;
        for sample times the argument is ``sample_times[<index>]`` of the first bad one (or
        ``sample_times.shape``).
    """
    for name, value in (("dt", dt), ("t_end", t_end)):
        if not (isinstance(value, (int, float, np.floating, np.integer)) and np.isfinite(value)
                and value > 0):
            raise _bad(name, value, "must be a finite number > 0")
    dt, t_end = float(dt), float(t_end)
    if not _on_grid(np.array([t_end]), dt).all() or round(t_end / dt) < 1:
        raise _bad("t_end", t_end, f"must be an integer multiple of dt = {dt!r} "
                                   f"(relative tolerance {GRID_RTOL:g})")
    times = np.asarray(sample_times, dtype=float)
    if times.ndim != 1:
        raise _bad("sample_times.shape", times.shape, "must be 1-D")
    rules = (
        (~np.isfinite(times), "must be finite"),
        (np.append(False, np.diff(times) <= 0), "must be strictly increasing"),
        ((times < 0) | (times > t_end * (1 + GRID_RTOL)), f"must lie in [0, t_end = {t_end!r}]"),
        (~_on_grid(times, dt) if fixed_step else np.zeros(times.shape, bool),
         f"must be integer multiples of dt = {dt!r} for a fixed-step method "
         f"(relative tolerance {GRID_RTOL:g})"),
    )
    for broken, rule in rules:
        if broken.any():
            index = int(np.argmax(broken))
            raise _bad(f"sample_times[{index}]", float(times[index]), rule)
    return times


def _on_grid(times: np.ndarray, dt: float) -> np.ndarray:
    """Whether each time is an integer multiple of ``dt`` within :data:`GRID_RTOL`."""
    return np.abs(times - np.rint(times / dt) * dt) <= GRID_RTOL * np.maximum(times, dt)


def divergence_reason(states: BodyStates, limit: float = DIVERGENCE_LIMIT) -> str | None:
    """Why ``states`` count as diverged, or None: a non-finite position, quaternion, velocity or
    angular velocity, or a position, velocity or angular-velocity norm above ``limit``."""
    fields = {"position": "m", "quaternion": "", "velocity": "m/s", "angular_velocity": "rad/s"}
    for name in fields:
        if not np.all(np.isfinite(getattr(states, name))):
            return f"non-finite {name.replace('_', ' ')}"
    for name, unit in fields.items():
        if unit:
            largest = float(np.max(np.linalg.norm(getattr(states, name), axis=-1), initial=0.0))
            if largest > limit:
                return f"{name.replace('_', ' ')} {largest:.3g} {unit} exceeds {limit:g}"
    return None


@dataclass(frozen=True)
class RunGrid:
    """The checked times of one run.

    Attributes
    ----------
    dt : float
        Step (first-step hint of an adaptive method), s.
    t_end : float
        s.
    sample_times : ndarray, shape (k,)
        s.
    fixed_step : bool
    """

    dt: float
    t_end: float
    sample_times: np.ndarray
    fixed_step: bool

    def steps(self, t: float) -> int:
        """Number of fixed steps from 0 to ``t``: round(t / dt)."""
        return int(round(t / self.dt))


class Stepper(abc.ABC):
    """Engine-specific stepping of one run, driven by :meth:`Adapter.simulate`.

    Modelled on ``scipy.integrate.OdeSolver``: the adapter's template owns the times, the checks,
    the samples and the status; a stepper only advances its engine (:meth:`_step_to`) and reads
    body states (:meth:`_states`).

    Attributes
    ----------
    steps : int
        Engine steps taken so far.
    t_good : float or None
        Time of the last state the engine produced and its own per-step checks passed, s, when
        the stepper tracks it (None: only the states the loop reads are known good).
    notes : list of str
        Facts a reader of the case must know.
    source : str
        Names a third-party adapter in the reason of a run its code ended (:func:`blame`); set
        by :meth:`Adapter.simulate` from :attr:`Adapter.source`.
    """

    source: str = ""
    #: Seconds :meth:`_step_to` spent on one-time work that is not stepping (compiling a loop a
    #: run needed only once it ran), left out of the run's wall time; a note should say so.  A
    #: class attribute until a stepper adds to it, so a stepper that never does (and one that
    #: does not call this ``__init__``) reads 0.
    untimed_s: float = 0.0

    def __init__(self):
        self.steps = 0
        self.t_good: float | None = None
        self.notes: list[str] = []

    @abc.abstractmethod
    def _step_to(self, t: float) -> None:
        """Advance the engine to time ``t`` (s, never earlier than the last call).

        Raises :class:`RunFailure` when the engine stops or detects divergence; any other
        exception ends the run as ``failed``.
        """

    @abc.abstractmethod
    def _states(self, t: float) -> BodyStates:
        """Body states at ``t`` (s), the time of the last :meth:`_step_to` call or, for adaptive
        methods, a time inside the last step."""

    def counters(self) -> dict:
        """Cost counters of the run so far (``rhs_evals``, ``jacobian_evals`` …)."""
        return {}

    def divergence(self, states: BodyStates) -> str | None:
        """An engine-specific divergence check on top of :func:`divergence_reason` (None: fine)."""
        return None

    def close(self) -> None:  # noqa: B027 — an optional hook: most steppers hold nothing
        """Release engine resources (called once, after the run)."""

    def run(self, grid: RunGrid, n_bodies: int) -> Trajectory:
        """Step through every sample time and on to ``grid.t_end``; every way the run ends
        becomes a status (see the module notes)."""
        times, states = [], []
        last_good, wall, read_back = 0.0, 0.0, 0.0
        status, reason, failure_time = CaseStatus.OK, "", None
        targets = np.asarray(grid.sample_times, dtype=float).tolist()  # floats, not numpy scalars
        if not targets or targets[-1] < grid.t_end * (1 - GRID_RTOL):
            targets.append(float(grid.t_end))
        try:
            for index, t in enumerate(targets):
                began = time.perf_counter()
                try:
                    self._step_to(t)
                finally:
                    wall += time.perf_counter() - began
                began = time.perf_counter()
                current = self._states(t)
                read_back += time.perf_counter() - began
                broken = malformed(current, n_bodies)
                if broken:
                    raise _ContractBroken(f"_states({t:g}) {broken}")
                bad = divergence_reason(current) or self.divergence(current)
                if bad:
                    raise _CheckFailed(bad)
                last_good = t
                if index < len(grid.sample_times):
                    times.append(t)
                    states.append(current)
        except _CheckFailed as error:
            status, reason, failure_time = CaseStatus.DIVERGED, str(error), last_good
        except RunFailure as error:
            status, reason, failure_time = error.status, error.reason, self._last_good(last_good)
        except _ContractBroken as error:
            status, reason, failure_time = (CaseStatus.FAILED,
                                            blame(self.source, "the run", str(error)), last_good)
        except Exception as error:  # noqa: BLE001 — a failure is a result (design rule 6)
            status, reason, failure_time = (CaseStatus.FAILED,
                                            blame(self.source, "the run", error),
                                            self._last_good(last_good))
        wall -= self.untimed_s
        run = dict(status=status, reason=reason, failure_time=failure_time, wall_time_s=wall,
                   read_back_s=read_back, steps=self.steps, counters=self.counters(),
                   notes=list(self.notes))
        if not states:
            return Trajectory.empty(n_bodies, **run)
        return Trajectory.from_samples(times, states, **run)

    def _last_good(self, checked: float) -> float:
        """The later of the last state this loop checked and the stepper's own last good one."""
        return checked if self.t_good is None else max(checked, float(self.t_good))


class _CheckFailed(Exception):
    """A state read by the run loop failed the divergence check."""


class _ContractBroken(Exception):
    """A stepper returned states that are not body states of the mechanism (:func:`malformed`)."""


@dataclass(frozen=True)
class MethodSpec:
    """One method an adapter offers.

    ``params`` maps each parameter name to its default value; ``description`` says what it is.
    """

    name: str
    description: str
    params: dict = field(default_factory=dict)

    def resolve(self, given: dict) -> dict:
        """Defaults overridden by ``given``; unknown keys raise a ValueError naming the valid ones."""
        unknown = sorted(set(given) - set(self.params))
        if unknown:
            valid = ", ".join(sorted(self.params)) or "none"
            raise ValueError(f"method {self.name!r} has no parameter {', '.join(unknown)} "
                             f"(valid: {valid})")
        resolved = dict(self.params)
        for key, value in given.items():
            default = self.params[key]
            resolved[key] = _coerce(key, value, default)
        return resolved


def _coerce(key: str, value: str, default):
    if isinstance(default, bool):
        if value.lower() in ("1", "true", "yes", "on"):
            return True
        if value.lower() in ("0", "false", "no", "off"):
            return False
        raise ValueError(f"parameter {key!r} expects true/false, got {value!r}")
    if isinstance(default, (int, float)) and not isinstance(default, bool):
        try:
            number = float(value)
        except ValueError:
            raise ValueError(f"parameter {key!r} expects a number, got {value!r}") from None
        return int(number) if isinstance(default, int) and number.is_integer() else number
    return value


def parse_method(text: str) -> tuple[str, dict]:
    """Split ``"NAME:key=value,key=value"`` into ``(NAME, {key: value})`` (values as strings)."""
    name, _, rest = text.partition(":")
    params = {}
    for item in filter(None, (part.strip() for part in rest.split(","))):
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise ValueError(f"method {text!r}: expected key=value, got {item!r}")
        params[key.strip()] = value.strip()
    if not name.strip():
        raise ValueError(f"method {text!r}: empty method name")
    return name.strip(), params


class Adapter(abc.ABC):
    """Base class of every engine adapter (registered by name in :mod:`adapters`).

    Attributes
    ----------
    name : str
        Registry name; :func:`adapters.get_adapter` sets it to the name the adapter is
        registered under.
    package : str
        ``"NAME VERSION"`` of the distribution providing a third-party adapter, set by
        :func:`adapters.get_adapter` from its entry point; ``""`` for a built-in adapter.
    """

    name: str = ""
    package: str = ""

    @property
    def source(self) -> str:
        """Names a third-party adapter and its package in failure reasons (:func:`blame`):
        ``adapter 'toy' from package mbh-toy-adapter 0.1.0``; ``""`` for a built-in adapter."""
        return adapter_label(self.name, self.package) if self.package else ""

    @abc.abstractmethod
    def version(self) -> str:
        """Engine name and version, e.g. ``"mujoco 4.0.0"``."""

    @abc.abstractmethod
    def methods(self) -> list[MethodSpec]:
        """Every method, including ``default`` and ``best``."""

    @abc.abstractmethod
    def build(self, mechanism: Mechanism):
        """Engine model of ``mechanism``; raises :class:`UnsupportedCase` with a reason."""

    def export(self, mechanism: Mechanism) -> str:
        """The engine's own model file for ``mechanism`` (text), for ``mbh export``.

        Raises
        ------
        UnsupportedCase
            When the engine has no model file format (this default) or cannot represent
            ``mechanism``.
        """
        raise UnsupportedCase(f"the {self.name} adapter has no model file to export")

    def model_size(self, model) -> dict:
        """What the engine carries for the mechanism of ``model`` (from :meth:`build`).

        Returns
        -------
        dict
            ``coordinates`` (int: generalized position coordinates the engine integrates),
            ``constraint_equations`` (int: constraint rows it enforces), ``redundant_equations``
            (int: rows among those that are linear combinations of the others) and ``notes``
            (str: how they were counted).  This default reports nothing (None counts, a note
            saying so); every shipped adapter overrides it.
        """
        return {"coordinates": None, "constraint_equations": None, "redundant_equations": None,
                "notes": f"the {self.name} adapter does not report its model size"}

    def method_model_size(self, model, method: str) -> dict:
        """What the engine carries for the mechanism of ``model`` when it runs ``method``: the
        same dict as :meth:`model_size`, which it returns unless a method changes the model (the
        in-house adapter's ``coords=joint``).  Override it only for such methods."""
        return self.model_size(model)

    def bare_loop(self, model, method: str, dt: float, n_steps: int) -> float:
        """Wall time (s) of the engine's own stepping loop alone: ``n_steps`` steps of ``method``
        from the harness's assembled start, with the settings :meth:`simulate` uses, but no
        samples, no state read-back and no per-step checks — the yardstick of the adapter's
        overhead (``mbh bench`` prints simulate's time per step over this one's).

        Raises
        ------
        UnsupportedCase
            When the adapter has no bare loop for this method (this default).
        """
        raise UnsupportedCase(f"the {self.name} adapter has no bare loop to time")

    def simulate(self, model, method: str, dt: float, t_end: float,
                 sample_times: np.ndarray) -> Trajectory:
        """Run ``method`` from the harness's assembled state and sample every body.

        Parameters
        ----------
        model
            From :meth:`build`.
        method : str
            ``NAME[:key=value,...]``, see :meth:`methods`.
        dt : float
            Step (first-step hint of an adaptive method), s.
        t_end : float
            End time, s; an integer multiple of ``dt``.
        sample_times : ndarray, shape (k,)
            Increasing times in [0, t_end], s; on the step grid for fixed-step methods.

        Returns
        -------
        Trajectory
            Failures are a status with the samples before them (see the module notes).

        Raises
        ------
        ValueError
            For an unknown method or parameter, or times that break :func:`check_run_times`.
        """
        spec, params = self.method_spec(method)
        self._check_params(spec, params)
        fixed = self._fixed_step(spec, params)
        times = check_run_times(dt, t_end, sample_times, fixed_step=fixed)
        grid = RunGrid(float(dt), float(t_end), times, fixed)
        n_bodies = len(self._mechanism(model).bodies)
        try:
            stepper = self._start(model, spec, params, grid)
        except UnsupportedCase as error:
            return Trajectory.empty(n_bodies, status=CaseStatus.UNSUPPORTED, reason=str(error))
        except Exception as error:  # noqa: BLE001 — a refused start is a result (rule 6)
            return Trajectory.empty(n_bodies, status=CaseStatus.FAILED,
                                    reason=blame(self.source, "_start", error), failure_time=0.0)
        stepper.source = self.source
        try:
            return stepper.run(grid, n_bodies)
        finally:
            stepper.close()

    @abc.abstractmethod
    def _start(self, model, spec: MethodSpec, params: dict, grid: RunGrid) -> Stepper:
        """A :class:`Stepper` holding the engine at the harness's assembled start (t = 0).

        Raises :class:`UnsupportedCase` when the engine cannot run this method on this model; any
        other exception makes the run ``failed`` at t = 0 with no samples.
        """

    def _check_params(self, spec: MethodSpec, params: dict) -> None:  # noqa: B027 — optional hook
        """Raise a ValueError for resolved parameters the engine cannot take (default: none)."""

    def _fixed_step(self, spec: MethodSpec, params: dict) -> bool:
        """Whether the method takes steps of exactly ``dt`` (default: True)."""
        return True

    def _mechanism(self, model) -> Mechanism:
        """The mechanism a built model represents (default: ``model.mechanism``)."""
        return model.mechanism

    def method_spec(self, method: str) -> tuple[MethodSpec, dict]:
        """Look up ``method`` and resolve its parameters; unknown names list the valid ones."""
        name, given = parse_method(method)
        specs = {spec.name: spec for spec in self.methods()}
        if name not in specs:
            raise ValueError(f"unknown {self.name} method {name!r}; valid: {', '.join(specs)}")
        return specs[name], specs[name].resolve(given)
