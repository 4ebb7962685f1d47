"""One case from Python: a scene (by name, path or built mechanism), an adapter (registered by
name, or a class or instance that is not registered), a method and a step → a
:class:`~mbh._harness.run.case.CaseResult` with its status, reason, metrics, trajectory and the row
a campaign would store (``to_frame()``).

The inputs are checked before anything runs, with the rules a campaign file's cases obey
(:mod:`mbh._harness.run.spec`); every problem is named by its argument in one :class:`CaseInputError`.
What the engine does with a valid case is a result (the row's status), never an exception.
"""

from __future__ import annotations

import math
from pathlib import Path

from mbh._adapters import AdapterChoiceError, adapter_names, resolve_adapter
from mbh._adapters.base import Adapter, steps_in
from mbh._harness.common.errors import MbhError
from mbh._harness.measure.verdict import DEFAULT_ACCURACY, DEFAULT_BOUNDS, Bounds
from mbh._harness.model import scenario
from mbh._harness.model.mechanism import Mechanism
from mbh._harness.model.timegrid import steps_per_sample
from mbh._harness.run.case import CaseResult
from mbh._harness.run.row import run_spec
from mbh._harness.run.spec import CaseSpec

#: Most steps a case may take (a longer run is an input error, not hours of computing).
MAX_STEPS = 1e8


class CaseInputError(MbhError, ValueError):
    """Raised once with every problem of a case's arguments, each as ``argument: problem``."""

    def __init__(self, problems: list[str]):
        self.problems = problems
        super().__init__("\n".join(problems))


def _checked_step(dt, t_end: float, mech: Mechanism, problems: list[str]) -> None:
    """Record why ``dt`` (s) cannot run ``mech`` to ``t_end`` (s), if it cannot."""
    if isinstance(dt, bool) or not isinstance(dt, (int, float)) or not math.isfinite(dt) or dt <= 0:
        problems.append(f"dt: expected a finite step > 0 (s), got {dt!r}")
        return
    try:
        steps_per_sample(float(dt), mech.sample_step)
        steps = steps_in(float(dt), t_end)
    except ValueError as error:
        problems.append(f"dt: {error}")
        return
    if steps > MAX_STEPS:
        problems.append(f"dt: step {dt:g} s would take {t_end / dt:.3g} steps to {t_end:g} s "
                        f"(at most {MAX_STEPS:.0e}); give a larger step")


def _checked_adapter(adapter, method: str, problems: list[str]) -> Adapter | None:
    """The adapter ``adapter`` stands for (:func:`mbh._adapters.resolve_adapter`), with ``method``
    checked by it; None, the problem recorded, when it cannot be had."""
    if isinstance(adapter, str) and adapter not in adapter_names():
        problems.append(f"adapter: unknown adapter {adapter!r} (known: "
                        f"{', '.join(adapter_names())})")
        return None
    try:
        resolved = resolve_adapter(adapter)
    except AdapterChoiceError as error:
        problems.append(f"adapter: {error}")
        return None
    try:
        resolved.method_spec(method)
    except ValueError as error:
        problems.append(f"method: {error}")
    return resolved


def _checked_case(mech: Mechanism, adapter, method: str, dt, t_end,
                  repetitions) -> tuple[Adapter, float]:
    """(the adapter, the end time in s) of a case whose arguments all hold; raises
    :class:`CaseInputError` with every problem otherwise (see :func:`check_case`)."""
    problems = []
    resolved = _checked_adapter(adapter, method, problems)
    duration = mech.duration if t_end is None else t_end
    if isinstance(duration, bool) or not isinstance(duration, (int, float)) \
            or not 0 < duration <= mech.duration:
        problems.append(f"t_end: expected a time in (0, {mech.duration!r}] s, got {t_end!r}")
    else:
        _checked_step(dt, float(duration), mech, problems)
    if isinstance(repetitions, bool) or not isinstance(repetitions, int) or repetitions < 1:
        problems.append(f"repetitions: expected an integer >= 1, got {repetitions!r}")
    if problems:
        raise CaseInputError(problems)
    return resolved, float(duration)


def check_case(mech: Mechanism, adapter: str | type[Adapter] | Adapter, method: str, dt, t_end,
               repetitions=1) -> float:
    """Check a case's arguments against ``mech`` before anything runs.

    Parameters
    ----------
    mech : Mechanism
        The loaded scene.
    adapter, method, dt, t_end, repetitions
        As :func:`run_one`'s.

    Returns
    -------
    float
        The end time, s (``t_end``, or the scene's duration when it is None).

    Raises
    ------
    CaseInputError
        With every problem, each naming its argument.
    AdapterLoadError
        A registered adapter that cannot be loaded, or a class that fails to construct.
    """
    return _checked_case(mech, adapter, method, dt, t_end, repetitions)[1]


def run_one(scene: str | Path | Mechanism, adapter: str | type[Adapter] | Adapter,
            method: str = "best", dt: float = 1e-3, t_end: float | None = None, *,
            repetitions: int = 1, bounds: Bounds = DEFAULT_BOUNDS,
            accuracy: float = DEFAULT_ACCURACY) -> CaseResult:
    """Run one case against the scene's verified reference (built on first use) and measure it.

    Parameters
    ----------
    scene : str, Path or Mechanism
        A shipped scenario name, a scenario file, or a mechanism built in Python
        (:class:`mbh.MechanismBuilder`).
    adapter : str, Adapter subclass or Adapter
        A registered adapter's name (``mbh adapters``), or your own adapter as a class
        (instantiated without arguments) or an instance, registered or not
        (:mod:`mbh.adapters`).  Its case is judged and its row built exactly as a registered
        adapter's; the row's ``adapter`` is the adapter's ``name`` (a registered class's: its
        registered name).
    method : str
        Method string ``NAME[:key=value,...]`` (``mbh methods --adapter NAME``).
    dt : float
        Step, s: divides the scene's evaluation step and ``t_end``.
    t_end : float, optional
        End time, s, at most the scene's duration (default: the duration).
    repetitions : int
        Timed runs (the wall time is their median; the metrics come from the first).
    bounds : Bounds
        The verdict's bounds.
    accuracy : float
        Threshold on the main output's error (rad or m) for the ``accurate`` column.

    Returns
    -------
    CaseResult
        ``status``, ``reason``, ``metrics``, ``trajectory``, ``row`` and ``to_frame()``.

    Raises
    ------
    ScenarioError
        The scene does not load (every problem, naming the file and field).
    CaseInputError
        Any other argument is invalid (every problem, naming the argument); an adapter class or
        instance without a ``name``, or named like another registered adapter, is one.
    AdapterLoadError
        A registered adapter that cannot be loaded, or an adapter class that fails to construct
        (the message names it).
    """
    mech = scene if isinstance(scene, Mechanism) else scenario.load(scene)
    resolved, duration = _checked_case(mech, adapter, method, dt, t_end, repetitions)
    name = mech.name if isinstance(scene, Mechanism) else str(scene)
    spec = CaseSpec(name, resolved.name, method, float(dt), duration, repetitions)
    return run_spec(spec, bounds, accuracy, mech=mech, adapter=resolved)
