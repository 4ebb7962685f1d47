"""``mbh warm-up``: compile, ahead of the first runs on a machine, what the in-house
formulation's runs compile on first use, on every core at once.

The in-house kernels and loops are compiled by numba at their first use and cached per machine
and code (docs/speed.md, "Caches"): a fresh machine, or a new version of the kernels, pays a few
minutes once.  A test suite's workers or a campaign's cases would each meet that wait at a
different place (one process compiles, the others wait on its lock,
:mod:`mbh._adapters.inhouse.stepping.on_demand`); the warm-up pays it up front, with the cores in parallel,
and says so.  ``make test`` and ``make report`` run it first: the measured choice between this and
compiling at install time is in docs/speed.md, "What a first run compiles".

The work is a list of tiny in-house cases, each of which compiles one part, in phases: a phase's
cases run in parallel processes, and a phase starts once the previous one has ended, because its
cases load what the previous one compiled (the multistep loops call the one-step loop's step
and projection).  The loops call the kernels' right-hand side through its address
(:mod:`mbh._adapters.inhouse.stepping.native_call`), so the one-step loop compiles beside it
without waiting for it.  The other cases need nothing the phases compile, or wait on its locks:
the neutral reference routes of a scene that declares its branch, the DAE solver's kernels and
the joint-coordinate path (:data:`BESIDE_PHASES`), then the generated functions of the shipped
scenes' ``default`` and ``best``.  They run from the start on processes of their own, one more
than the phases have (:data:`FILL_EXTRA`), at a lower priority (:data:`FILL_NICENESS`): they
take the cores the phases leave idle, a process waiting on another's lock among them, without
slowing the phases' chain.  A case that fails is reported, not raised: the runs that need its
part compile it themselves.
"""

from __future__ import annotations

import multiprocessing
import os
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, as_completed, wait
from dataclasses import dataclass

from mbh._harness.common import waits
from mbh._harness.common.status import CaseStatus

#: (scene, method, dt s, t_end s, what it compiles) of each phase, longest first.
PHASES = (
    # The loops call the right-hand side through its address (stepping/native_call.py), not
    # its code: the one-step loop compiles beside it, on the other process.
    (("fourbar", "rk4+baumgarte:loop=python", 1e-3, 0.002,
      "the kernels' right-hand side and the start's kernels"),
     ("fourbar", "rk4+baumgarte:loop=compiled", 1e-3, 0.002,
      "the one-step and partitioned methods' loop")),
    # These call the one-step loop's step and projection (the multistep methods' start).
    (("fourbar", "bdf2+baumgarte:loop=compiled", 1e-3, 0.004, "the implicit multistep loop"),
     ("fourbar", "ab2+baumgarte:loop=compiled", 1e-3, 0.004, "the explicit multistep loop")),
)
#: Cases that call nothing the phases compile but the kernels they share with the right-hand
#: side (each waits on those kernels' locks and loads them): the first of the fill cases, so
#: that they run while the one-step loop compiles instead of after it.  The joint-coordinate
#: loops call the joint right-hand side through its address: each compiles its own loop (one
#: entry per method family and per treatment with or without the projection), then loads the
#: right-hand side and the solves the Python path's case compiles (waiting on their locks).
BESIDE_PHASES = (
    ("fourbar", "ida", 1e-3, 0.002, "the DAE solver's kernels"),
    ("fourbar", "rk4+direct:coords=joint,loop=python", 1e-3, 0.002,
     "the joint-coordinate path's right-hand side and solves (called from Python)"),
    ("fourbar", "ab5+baumgarte:coords=joint", 1e-3, 0.006,
     "the joint-coordinate loop of Adams–Bashforth"),
    ("fourbar", "rk4+direct:coords=joint", 1e-3, 0.002,
     "the joint-coordinate loop of the one-step methods with direct's projection"),
    ("fourbar", "rk4+baumgarte:coords=joint", 1e-3, 0.002,
     "the joint-coordinate loop of the one-step methods"),
)
#: Scenes whose ``default`` and ``best`` generated functions fill idle processes, at a run long
#: enough for ``loop=auto`` to make them.
FILL_SCENES = ("fourbar", "slider_crank_planar", "simple_pendulum", "fourbar_spatial",
               "slider_crank", "double_fourbar", "parallelogram_fourbar", "stiff_fourbar",
               "andrews")
#: Scenes whose neutral reference routes (harness/references/routes.py: kernels of
#: harness/neutral) fill idle processes too: the routes of a scene that declares its branch.
NEUTRAL_FILL_SCENES = ("double_fourbar",)
#: The method name of a fill case that runs a scene's neutral reference routes.
NEUTRAL_ROUTES = "neutral reference routes"
#: Nice increment of the fill cases' processes (Unix): under contention a phase's process gets
#: ~9 of every 10 time slices (Linux's weights: 1024 against 110), so the fill cases use the
#: cores the phases leave idle without lengthening the chain of phases.
FILL_NICENESS = 10
#: Fill processes beyond ``jobs`` (the phases' processes), so that a fill case waiting on a
#: lock (the joint-coordinate loops wait on each other's, the DAE solver on the right-hand
#: side's) leaves its core to another fill case instead of idle.  Measured on the 2-core
#: machine, empty caches, one after the other (docs/speed.md): 121 and 126 s with two fill
#: processes and the neutral routes last, 116 s with them first, 111 and 115 s with them
#: first and a third fill process (CPU the same, ~215 s).
FILL_EXTRA = 1
#: Measured length of a cold warm-up on the 2-core machine, s (docs/speed.md: 108–115 s on
#: 2026-11-30, with a margin for a busier machine): the announcement.
ESTIMATE_S = 130.0


@dataclass(frozen=True)
class WarmCase:
    """One case of the warm-up and what it compiles."""

    scene: str
    method: str
    dt: float
    t_end: float
    what: str

    @property
    def label(self) -> str:
        return f"{self.scene} {self.method}"


@dataclass(frozen=True)
class Warmed:
    """What one case of the warm-up did: its wall time (s) and, if it failed, why."""

    case: WarmCase
    seconds: float
    problem: str = ""


def _fill_cases() -> list[WarmCase]:
    """The neutral reference routes of :data:`NEUTRAL_FILL_SCENES` (the longest fill case, ~25
    s, and one that waits on no lock: started first, it no longer ends the warm-up alone), then
    :data:`BESIDE_PHASES`, then the generated functions of :data:`FILL_SCENES`' default and best
    (``loop=generated``)."""
    return [WarmCase(scene, NEUTRAL_ROUTES, 1e-3, 0.002, "the neutral reference kernels")
            for scene in NEUTRAL_FILL_SCENES] + [WarmCase(*case) for case in BESIDE_PHASES] + [
        WarmCase(scene, f"{alias}:loop=generated", 1e-3, 0.002,
                 f"{scene}'s generated functions ({alias})")
        for scene in FILL_SCENES for alias in ("rk4+baumgarte", "rk4+direct")]


def _run(case: WarmCase) -> Warmed:
    """Run ``case`` in this process (a fresh interpreter of the pool)."""
    began = time.perf_counter()
    try:
        import numpy as np

        from mbh._adapters import get_adapter
        from mbh._harness.model import scenario
        from mbh._harness.references.routes import full_route, reduced_route

        mech = scenario.load(case.scene)
        if case.method == NEUTRAL_ROUTES:
            grid = np.array([0.0, case.t_end])
            trajectories = [full_route(mech, grid), reduced_route(mech, grid)]
        else:
            trajectories = [get_adapter("inhouse").simulate(mech, case.method, case.dt,
                                                            case.t_end, np.zeros(1))]
        problem = "; ".join(f"{t.status}: {t.reason}" for t in trajectories
                            if t.status != CaseStatus.OK)
    except Exception as error:  # noqa: BLE001 — a failed warm-up case only costs a later wait
        problem = f"{type(error).__name__}: {error}"
    return Warmed(case, time.perf_counter() - began, problem)


def _lower_priority() -> None:
    """Initializer of the fill cases' processes: :data:`FILL_NICENESS` (where the system has it)."""
    if hasattr(os, "nice"):
        os.nice(FILL_NICENESS)


def warm_up(jobs: int) -> list[Warmed]:
    """Run :data:`PHASES` on ``jobs`` processes and, from the start, the fill cases
    (:func:`_fill_cases`) on ``jobs`` + :data:`FILL_EXTRA` processes of lower priority; every
    case's :class:`Warmed`, in the order they ended."""
    done: list[Warmed] = []

    def record(future) -> None:
        warmed = future.result()
        done.append(warmed)
        waits.LOG.info("warm-up: %s (%s) %.0f s%s", warmed.case.label, warmed.case.what,
                       warmed.seconds, f": {warmed.problem}" if warmed.problem else "")

    context = multiprocessing.get_context("spawn")  # fresh interpreters: nothing inherited
    with waits.said(f"compiling the in-house kernels and loops on {jobs} process(es)",
                    "once per machine and version of the kernels", ESTIMATE_S), \
            ProcessPoolExecutor(max_workers=jobs, mp_context=context) as phases, \
            ProcessPoolExecutor(max_workers=jobs + FILL_EXTRA, mp_context=context,
                                initializer=_lower_priority) as fill:
        running = {fill.submit(_run, case) for case in _fill_cases()}
        for phase in PHASES:
            own = {phases.submit(_run, WarmCase(*case)) for case in phase}
            running |= own
            while own:
                finished, running = wait(running, return_when=FIRST_COMPLETED)
                for future in finished:
                    record(future)
                own -= finished
        for future in as_completed(running):
            record(future)
    return done
