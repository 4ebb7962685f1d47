"""Verified reference solutions, cached on disk by scenario content hash.

A reference is the in-house formulation's most accurate configuration, computed by two routes on
the same dense time grid, both the index-1 augmented form with direct position and velocity
projection after every step (Rouvinen 2003, eq. 77, 127, 137) at Δt = 5e-5 s, integrated by two different
method families:

* route A (:data:`ROUTE_A`): the classical Runge–Kutta RK4 on the first-order system;
* route B (:data:`ROUTE_B`): the Runge–Kutta–Nyström RKN4 on the second-order system.

Their largest difference over the whole run — every position-level output and every body's centre
of mass, in rad and m — is stored with the reference and must not exceed :data:`AGREEMENT_LIMIT`.
Route A's trajectory is the reference.

Routes A and B share the in-house constraint and dynamics code and differ only in the integrator, so
a modelling error in that code (a wrong joint equation, inertia or γ term) would pass their
agreement and make the in-house engine the measure of itself. Every reference therefore also agrees,
within the same limit and by the same measure, with a route that uses no contestant's code, its
independent route (:func:`independent_route`, stored as ``independent`` in the metadata): here
:data:`INDEPENDENT_ROUTE`, DOP853 at rtol = atol = 1e-13 on the harness's own joint equations and
Newton–Euler dynamics (:func:`~mbh._harness.references.routes.full_route`), compared with route A at
every sample of the whole run; it costs 1–7 s a scene (route A 0.02–0.9 s on the compiled loop, the
informational IDA check up to 100 s) and agrees to 3.6e-13 … 1.6e-10. A planted error in the
in-house tables or γ is refused by it (tests/references/test_independent_route.py). The
informational route stored here runs SUNDIALS IDA on the stabilised index-2 DAE (:data:`DAE_CHECK`),
on the in-house equations too; IDA's corrector fails below rtol ≈ 1e-13, which keeps it short of the
agreement limit on some scenes, so it is reported, not required. Adaptive DOP853 on the partitioned
form and fixed-step partitioning were rejected as routes: neither reaches the agreement limit on the
spatial slider-crank (the reduced ODE steepens near a fold of the independent coordinate, see the
in-house ``partition`` method). Figures: docs/measurements.md, section "References".

A scene that passes singular positions and declares the branch it stays on (``[reference]
equal_joint_angles``, e.g. ``double_fourbar``), or that asks for them (``[reference] routes =
"neutral"``: fast or stiff scenes where a fixed 5e-5 s step cannot reach the limit), uses two
other routes, :data:`BRANCH_ROUTE_A` (every
body, index-1 Newton–Euler with the branch's rows) and :data:`BRANCH_ROUTE_B` (the driver
coordinate alone, reduced along the branch), both DOP853 on the harness's neutral joint equations: the
RK4/RKN4 routes lose the branch's accuracy at every passage, see
:mod:`mbh._harness.references.routes`.  There route A is itself the independent route, checked
against route B.  Either way route A must also satisfy the plain joint equations within the
agreement limit.

Shipped scenes come with their references (``scenarios/references``); a reference built here goes
to the user cache (:mod:`mbh._harness.store.reference_files`: ``MBH_CACHE_DIR`` overrides both); a file is
keyed by the scenario's content hash and :data:`REFERENCE_VERSION`, so editing a scenario, or
bumping the version when the formulation changes, rebuilds it. On load the stored metadata must
match the scenario and the builder (name, content hash, version, grid step, routes, both agreements
within the limit, arrays on the grid), or the reference is rebuilt; files are written atomically
(unique temporary file, ``os.replace``), so processes of a pool can share the cache.

A build takes seconds to minutes (docs/measurements.md, "References").  On a terminal it shows a
progress bar with the time left (:class:`~mbh._harness.common.progress.StageProgress`), estimated from
a pilot run of each stage over the first :data:`PILOT_FRACTION` of the duration.  Each stage is
also said on the ``mbh`` logger (:mod:`mbh._harness.common.waits`: the command line's stderr lines),
with the time left; where neither bar nor lines are shown, no pilot runs.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import time

import numpy as np

from mbh._harness.references.routes import (ROUTE_TOLERANCE, BranchRouteError, full_route,
                                            reduced_route)
from mbh._harness.model.mechanism import Mechanism
from mbh._harness.model.outputs import output_series
from mbh._harness.common.status import CaseStatus
from mbh._harness.model.timegrid import GRID_STEP
from mbh._harness.model.trajectory import Trajectory
from mbh._harness.common.errors import MbhError
from mbh._harness.common import waits
from mbh._harness.common.progress import StageProgress, progress_wanted
from mbh._harness.store.reference_files import (AGREEMENT_LIMIT, REFERENCE_VERSION, cache_dir,
                                           read_reference, reference_grid, refusal_path,
                                           replace_atomically, write_reference)
from mbh._harness.measure.metrics import constraint_violations

#: Share of the duration a pilot run covers to estimate a stage's cost (progress bar only).
PILOT_FRACTION = 0.02
#: (method, step) of each route; IDA's step is only its first-step hint.
ROUTE_A = ("rk4+direct:proj_tol=1e-14", 5e-5)
ROUTE_B = ("rkn4+direct:proj_tol=1e-14", 5e-5)
DAE_CHECK = ("ida:rtol=1e-13,atol=1e-13,max_steps=5000000", GRID_STEP)
#: The routes of a scene that declares the branch it stays on (``[reference]
#: equal_joint_angles``): (route, DOP853 tolerance), see :mod:`mbh._harness.references.routes`.
#: The full route is route A (the reference): it is the closer of the two to the
#: one-degree-of-freedom model, since the reduced route's θ̈ carries the finite-difference noise
#: of γ times θ̇² (figures: docs/measurements.md, section "References").
BRANCH_ROUTE_A = ("branch-full:dop853", ROUTE_TOLERANCE)
BRANCH_ROUTE_B = ("branch-reduced:dop853", ROUTE_TOLERANCE)
#: The route that uses no contestant's code, required of every scene whose routes A and B are the
#: in-house ones: :func:`~mbh._harness.references.routes.full_route` on the scene's own joint
#: equations (no branch rows), DOP853 on the harness's neutral Newton–Euler equations.  It must
#: agree with route A within :data:`AGREEMENT_LIMIT` at every sample of the whole run.
INDEPENDENT_ROUTE = ("neutral-full:dop853", ROUTE_TOLERANCE)


def _neutral_full_route(mech: Mechanism, grid: np.ndarray) -> Trajectory:
    """The full route on ``mech``'s own joint equations, whether or not the scene asks for the
    neutral routes."""
    return full_route(dataclasses.replace(mech, neutral_routes=True), grid)


_NEUTRAL_ROUTES = {BRANCH_ROUTE_A[0]: full_route, BRANCH_ROUTE_B[0]: reduced_route,
                   INDEPENDENT_ROUTE[0]: _neutral_full_route}


class ReferenceBuildError(MbhError, RuntimeError):
    """The two routes did not agree, or a route failed; the message has the numbers."""


_POSITION_LEVEL = ("joint_angle", "joint_position", "position", "point_position")


def route_difference(mech: Mechanism, a: Trajectory, b: Trajectory) -> dict:
    """Largest differences between two trajectories on the same grid.

    ``max`` covers the position-level quantities the agreement limit applies to (outputs in rad
    or m and every body's centre of mass, m); velocity-level outputs (rad/s, m/s) are reported
    under ``velocity_outputs`` for information.
    """
    def difference(name):
        return float(np.abs(output_series(mech, a, name) - output_series(mech, b, name)).max())

    position = {o.name: difference(o.name) for o in mech.outputs if o.kind in _POSITION_LEVEL}
    velocity = {o.name: difference(o.name) for o in mech.outputs if o.kind not in _POSITION_LEVEL}
    bodies = float(np.abs(a.position - b.position).max())
    return {"outputs": position, "velocity_outputs": velocity, "body_position_m": bodies,
            "max": max([*position.values(), bodies])}


def routes(mech: Mechanism) -> tuple[tuple[str, float], tuple[str, float]]:
    """Routes A and B of ``mech``: the neutral (branch) routes for a scene that declares its
    branch or asks for them (``[reference] routes = "neutral"``), the in-house RK4/RKN4 routes
    otherwise."""
    return (BRANCH_ROUTE_A, BRANCH_ROUTE_B) if mech.neutral_routes else (ROUTE_A, ROUTE_B)


def independent_route(mech: Mechanism) -> tuple[str, float]:
    """The route of ``mech``'s reference that uses no contestant's code: route A itself on the
    neutral routes (checked against route B), else :data:`INDEPENDENT_ROUTE` (checked against
    route A)."""
    return BRANCH_ROUTE_A if mech.neutral_routes else INDEPENDENT_ROUTE


def _run_route(mech: Mechanism, route: tuple[str, float], grid: np.ndarray,
               t_end: float | None = None) -> Trajectory:
    """``route`` sampled on ``grid`` up to ``t_end`` (s; the scene's duration unless given)."""
    from mbh._adapters import get_adapter

    method, step = route
    if method in _NEUTRAL_ROUTES:
        try:
            return _NEUTRAL_ROUTES[method](mech, grid)
        except BranchRouteError as error:
            raise ReferenceBuildError(f"{mech.name}: reference route {method}: {error}") from error
    t_end = mech.duration if t_end is None else t_end
    trajectory = get_adapter("inhouse").simulate(mech, method, step, t_end, grid)
    if trajectory.status != CaseStatus.OK or trajectory.n_samples != grid.size:
        raise ReferenceBuildError(f"{mech.name}: reference route {method} (dt {step:g}) ended "
                             f"{trajectory.status} at t = {trajectory.failure_time}: "
                             f"{trajectory.reason}")
    return trajectory


def _estimate(mech: Mechanism, route: tuple[str, float], grid: np.ndarray) -> float:
    """Estimated wall time of ``route`` over the whole of ``grid``, s: a pilot run over its first
    :data:`PILOT_FRACTION`, whose stepping time is scaled up and whose fixed cost (assembly,
    loading compiled code) is added once; 0 when the pilot fails (the full run will say why)."""
    count = max(2, int(np.ceil(PILOT_FRACTION * (grid.size - 1))) + 1)
    pilot = grid[:count]
    began = time.perf_counter()
    try:
        trajectory = _run_route(mech, route, pilot, t_end=float(pilot[-1]))
    except ReferenceBuildError:
        return 0.0
    elapsed = time.perf_counter() - began
    stepping = min(trajectory.wall_time_s or elapsed, elapsed)
    return elapsed - stepping + stepping * (grid.size - 1) / (count - 1)


def _cost(trajectory: Trajectory) -> dict:
    return {"wall_time_s": trajectory.wall_time_s, "steps": trajectory.steps, **trajectory.counters}


def _dae_check(mech: Mechanism, route_a: Trajectory, grid: np.ndarray) -> dict:
    """Difference between IDA and route A, or why IDA did not finish (informational)."""
    try:
        dae = _run_route(mech, DAE_CHECK, grid)
    except ReferenceBuildError as error:
        return {"method": DAE_CHECK[0], "status": "failed", "reason": str(error)}
    return {"method": DAE_CHECK[0], "status": "ok", "difference": route_difference(mech, route_a, dae),
            "cost": _cost(dae)}


def _independent_check(mech: Mechanism, route_a: Trajectory, agreement: dict, grid: np.ndarray,
                       stage) -> dict:
    """The agreement of :func:`independent_route` with the other route of ``mech``'s reference;
    ``stage(name, work)`` runs the independent route when it is not route A.  Raises
    ReferenceBuildError above :data:`AGREEMENT_LIMIT`."""
    route = independent_route(mech)
    compared = {"route": list(route), "span_s": float(grid[-1]), "samples": int(grid.size),
                "grid_step": GRID_STEP, "limit": AGREEMENT_LIMIT}
    if mech.neutral_routes:  # route A is the independent route; its agreement is checked above
        return {**compared, "compared_with": "route B", "difference": agreement}
    run = stage(f"independent route {route[0]}", lambda: _run_route(mech, route, grid))
    difference = route_difference(mech, route_a, run)
    if not difference["max"] <= AGREEMENT_LIMIT:
        raise ReferenceBuildError(
            f"{mech.name}: route A (in-house) and the independent route {route[0]} (the "
            f"harness's neutral equations, no contestant's code) disagree by "
            f"{difference['max']:.3g} > {AGREEMENT_LIMIT:g}: a modelling error in one of the "
            f"two formulations ({json.dumps(difference)})")
    return {**compared, "compared_with": "route A", "difference": difference,
            "cost": _cost(run)}


def build_reference(mech: Mechanism, show_progress: bool | None = None) -> tuple[Trajectory, dict]:
    """Compute both routes, their agreement, the independent route's agreement and the DAE check
    (no cache); raises ReferenceBuildError when the routes differ by more than
    :data:`AGREEMENT_LIMIT`, route A violates the joint equations by more, or the independent
    route differs by more.  ``show_progress``: draw the progress bar (None: when stderr is a
    terminal)."""
    grid = reference_grid(mech)
    first, second = routes(mech)
    stages = ([first, second] + ([] if mech.neutral_routes else [INDEPENDENT_ROUTE])
              + ([] if mech.branch else [DAE_CHECK]))
    shown = progress_wanted(True) if show_progress is None else show_progress
    said = shown or waits.LOG.isEnabledFor(logging.INFO)
    estimates = [_estimate(mech, route, grid) for route in stages] if said else [0.0] * len(stages)
    with StageProgress(f"reference {mech.name}", estimates, shown) as bar:
        order = iter(range(len(stages)))

        def stage(name: str, work):
            index = next(order)
            left = sum(estimates[index:])
            waits.LOG.info("reference of %s: stage %d of %d, %s%s", mech.name, index + 1,
                           len(stages), name,
                           f" (~{waits.duration(left)} left)" if left > 0 else "")
            return bar.run(index, name, work)

        route_a = stage(f"route A {first[0]}", lambda: _run_route(mech, first, grid))
        route_b = stage(f"route B {second[0]}", lambda: _run_route(mech, second, grid))
        agreement = route_difference(mech, route_a, route_b)
        if agreement["max"] > AGREEMENT_LIMIT:
            raise ReferenceBuildError(f"{mech.name}: reference routes disagree by "
                                      f"{agreement['max']:.3g} > {AGREEMENT_LIMIT:g} "
                                      f"({json.dumps(agreement)})")
        joints = constraint_violations(mech, route_a)["max_constraint_violation"]
        if not joints <= AGREEMENT_LIMIT:
            raise ReferenceBuildError(f"{mech.name}: route A violates the joint equations by "
                                      f"{joints:.3g} m > {AGREEMENT_LIMIT:g}")
        independent = _independent_check(mech, route_a, agreement, grid, stage)
        dae = (stage("DAE check", lambda: _dae_check(mech, route_a, grid))
               if not mech.branch else None)
    info = {"scenario": mech.name, "content_hash": mech.content_hash,
            "version": REFERENCE_VERSION, "route_a": list(first), "route_b": list(second),
            "grid_step": GRID_STEP, "agreement": agreement, "max_constraint_violation": joints,
            "independent": independent,
            "route_a_cost": _cost(route_a), "route_b_cost": _cost(route_b),
            "dae_check": (dae if not mech.branch else
                          {"method": DAE_CHECK[0], "status": "skipped",
                           "reason": "not run on a scene with singular passages (IDA failed at the "
                                     "first one on double_fourbar, t = 0.71 s)"})}
    return route_a, info


def reference_trajectory(mech: Mechanism) -> Trajectory:
    """The verified reference of ``mech``, from the cache or built (and cached) now."""
    return load_or_build(mech)[0]


def reference_info(mech: Mechanism) -> dict:
    """The stored agreement and cost of ``mech``'s reference."""
    return load_or_build(mech)[1]


def load_or_build(mech: Mechanism, show_progress: bool | None = None) -> tuple[Trajectory, dict]:
    """``mech``'s reference and its metadata, from the cache when the stored files pass
    :func:`_stale_reason`, otherwise built and cached.

    Safe for concurrent processes: each file is written to a unique temporary file in the cache
    directory and moved into place with ``os.replace`` (atomic), data first and metadata last, so
    a reader sees either no metadata or metadata whose data is complete.  Processes that build the
    same reference at once write identical content; the last replace wins.  A refused build is
    recorded next to it (``<stem>.refused.json``: the reason, keyed like a reference), so later
    callers get the same ReferenceBuildError at once; delete the record to try again.

    Raises
    ------
    ReferenceBuildError
        When the routes fail or disagree (:func:`build_reference`), or the cache cannot be
        written.
    """
    cached = read_reference(mech, routes(mech))
    if cached is not None:
        return cached
    _raise_recorded_refusal(mech)
    try:
        with waits.said(f"building the verified reference of {mech.name}",
                        "once per scene and version: two routes must agree"):
            trajectory, info = build_reference(mech, show_progress)
    except ReferenceBuildError as error:
        _record_refusal(mech, error)
        raise
    try:
        write_reference(mech, trajectory, info)
    except OSError as error:
        raise ReferenceBuildError(f"{mech.name}: cannot write the reference cache in "
                                  f"{cache_dir()}: {error}") from error
    return trajectory, info


def _refusal_key(mech: Mechanism) -> dict:
    """What a recorded refusal must match to stand for today's builder and scenario."""
    return {"scenario": mech.name, "content_hash": mech.content_hash,
            "version": REFERENCE_VERSION, "grid_step": GRID_STEP,
            "route_a": list(routes(mech)[0]), "route_b": list(routes(mech)[1]),
            "independent_route": list(independent_route(mech)), "agreement_limit": AGREEMENT_LIMIT}


def _record_refusal(mech: Mechanism, error: ReferenceBuildError) -> None:
    """Keep why the build was refused, so that the next caller learns it at once instead of
    spending minutes on the same routes (failure is data; delete the file to try again)."""
    record = {**_refusal_key(mech), "refused": str(error)}
    try:
        replace_atomically(refusal_path(mech), lambda handle: handle.write(
            json.dumps(record, indent=2).encode()))
    except OSError:
        pass  # an unwritable cache only costs the next caller a rebuild


def _raise_recorded_refusal(mech: Mechanism) -> None:
    """Raise the recorded ReferenceBuildError of a refused build that still applies, if any."""
    try:
        record = json.loads(refusal_path(mech).read_text())
    except (OSError, ValueError):
        return
    if isinstance(record, dict) and all(record.get(k) == v for k, v in _refusal_key(mech).items()):
        raise ReferenceBuildError(f"{record.get('refused')} (recorded by an earlier build in "
                             f"{refusal_path(mech)}; delete it to build again)")
