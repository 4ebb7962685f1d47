"""Report figures drawn from stored campaign results: work-precision diagrams, stability maps and
the time histories of one case (issue 11).

Every function returns a :class:`~mbh._harness.report.style.Figure` (deterministic SVG and PDF, a
caption and a text alternative).  Nothing computed is hidden: a case that did not end ``ok``, or
that has no wall time or no value, is drawn at the edge of the plot and marked by its status.
"""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
import pandas as pd
from matplotlib.lines import Line2D
from matplotlib.patches import Patch, Rectangle
from matplotlib.colors import BoundaryNorm, ListedColormap

from mbh._harness.measure.energy import energy_balance, energy_scale
from mbh._harness.neutral.equations import JointEquations
from mbh._harness.measure.metrics import lever_length, violation_series
from mbh._harness.model.mechanism import Mechanism
from mbh._harness.model.outputs import output_series
from mbh._harness.common.numbers import float_or_nan
from mbh._harness.neutral.mobility import independent_rows
from mbh._harness.report.style import (OUTCOME_COLOURS, OUTCOME_LETTERS, REFERENCE_COLOUR, Figure,
                                  apply_style, new_figure, no_data, outcome, plain,
                                  render, series_style)
from mbh._harness.common.status import CaseStatus
from mbh._harness.model.timegrid import reference_indices
from mbh._harness.model.trajectory import Trajectory

#: The y quantities of a work-precision diagram → axis label.
Y_LABELS = {
    "main_output_error": "largest error of the main output (rad or m)",
    "max_constraint_violation": "largest constraint violation, m",
    "max_energy_error_rel": "largest energy-balance error / energy scale",
}
#: Marker of a point drawn off the chart, by its label (a status, or why an ok case has no place).
EDGE_MARKERS = {CaseStatus.DIVERGED: "X", CaseStatus.FAILED: "v", CaseStatus.CRASHED: "*",
                CaseStatus.TIMEOUT: "P", CaseStatus.UNSUPPORTED: "s", "no value": "o",
                "no time": "d", "zero": "^"}
#: Unit of each output kind (mbh._harness.model.mechanism.Output).
OUTPUT_UNITS = {"joint_angle": "rad", "joint_rate": "rad/s", "joint_position": "m",
                "position": "m", "velocity": "m/s", "point_position": "m",
                "point_velocity": "m/s"}
#: Fraction of the axes kept for points drawn at an edge (the shaded bands).
_BAND = 0.08
_FAILURE_COLOUR = "#D55E00"


def _scenario_rows(frame: pd.DataFrame, scenario: str, columns: tuple[str, ...],
                   what: str) -> pd.DataFrame:
    """The rows of ``scenario`` in ``frame``; an empty frame when there are none.

    Raises
    ------
    ValueError
        When ``frame`` has rows but lacks one of ``columns`` (named with ``what``).
    """
    if frame is None or frame.empty:
        return pd.DataFrame(columns=["scenario", *columns])
    missing = [name for name in ("scenario", *columns) if name not in frame.columns]
    if missing:
        raise ValueError(f"{what}: missing column(s) {', '.join(missing)}")
    return frame[frame["scenario"] == scenario].reset_index(drop=True)


def _log_limits(low: float, high: float, start: float, stop: float) -> tuple[float, float]:
    """Axis limits (log scale) that put log10 values [low, high] at axes fractions [start, stop]."""
    if high - low < 1e-9:
        low, high = low - 0.5, high + 0.5
    span = (high - low) / (stop - start)
    bottom = low - start * span
    return 10.0 ** bottom, 10.0 ** (bottom + span)


def _placement(status: str, time: float, value: float) -> tuple[str, str]:
    """Where a case goes on a work-precision diagram and its edge label.

    ``("ok", "ok")`` for a point on the chart; ``("top", status)`` for a case that did not end
    ``ok`` (or ``"no value"`` when it did but its value is missing); ``("left", …)`` when the wall
    time is zero or missing; ``("bottom", "zero")`` for an ok value of exactly 0.
    """
    if not (math.isfinite(time) and time > 0):
        return "left", status if status != CaseStatus.OK else "no time"
    if status != CaseStatus.OK:
        return "top", status
    if not (math.isfinite(value) and value >= 0):
        return "top", "no value"
    return ("bottom", "zero") if value == 0 else ("ok", "ok")


def pareto_front(cases: pd.DataFrame, y: str = "main_output_error") -> pd.DataFrame:
    """The ``ok`` cases no other ``ok`` case beats in both wall time and ``y``.

    Only cases with a positive wall time and a positive finite ``y`` compete (those the
    work-precision diagram draws as points).  Returns those rows sorted by wall time, ``y``
    decreasing along them.
    """
    if cases.empty:
        return cases
    time = cases["wall_time_s"].map(float_or_nan)
    value = cases[y].map(float_or_nan)
    mask = (cases["status"] == CaseStatus.OK) & (time > 0) & np.isfinite(time) & (value > 0) \
        & np.isfinite(value)
    candidates = cases[mask].assign(_t=time[mask], _v=value[mask]).sort_values(
        ["_t", "_v"], kind="stable")
    best = math.inf
    keep = []
    for label, v in zip(candidates.index, candidates["_v"]):
        if v < best:
            keep.append(label)
            best = v
    return candidates.loc[keep].drop(columns=["_t", "_v"])


def _series_label(adapter: str, method: str) -> str:
    return f"{adapter} · {method}"


def work_precision(cases: pd.DataFrame, scenario: str, y: str = "main_output_error") -> Figure:
    """Work-precision diagram of one scenario: ``y`` against wall time, log–log.

    One line per (adapter, method) through its ok cases sorted by dt, the smallest and largest dt
    written at the line's ends; the Pareto front (:func:`pareto_front`) as a grey step line.
    Cases that did not end ok sit at their wall time in the shaded top band, marked by status;
    cases with a zero or missing wall time sit in the left band; an ok value of exactly 0 in the
    bottom band.

    Parameters
    ----------
    cases : DataFrame
        Case rows of the store (columns scenario, adapter, method, dt, status, wall_time_s, ``y``).
    scenario : str
    y : {"main_output_error", "max_constraint_violation", "max_energy_error_rel"}

    Raises
    ------
    ValueError
        For another ``y`` or a frame without the columns.
    """
    if y not in Y_LABELS:
        raise ValueError(f"work_precision: y must be one of {', '.join(Y_LABELS)}, got {y!r}")
    title = f"{scenario}: {Y_LABELS[y].split(' (')[0]} against wall time"
    frame = _scenario_rows(cases, scenario, ("adapter", "method", "dt", "status", "wall_time_s",
                                             y), "work_precision cases")
    if frame.empty:
        return no_data(title, f"no cases of scenario {scenario}")
    frame = frame.assign(_t=frame["wall_time_s"].map(float_or_nan), _v=frame[y].map(float_or_nan))
    places = [_placement(s, t, v) for s, t, v in zip(frame["status"], frame["_t"], frame["_v"])]
    frame = frame.assign(_where=[p[0] for p in places], _label=[p[1] for p in places])
    series = sorted(set(zip(frame["adapter"], frame["method"])))
    front = pareto_front(frame, y)
    with apply_style():
        figure = new_figure(6.4, 4.4 + 0.17 * math.ceil((len(series) + 1) / 2))
        axes = figure.add_subplot()
        axes.set_xscale("log")
        axes.set_yscale("log")
        colours = {}
        for index, key in enumerate(series):
            style = series_style(index)
            colours[key] = style["color"]
            rows = frame[(frame["adapter"] == key[0]) & (frame["method"] == key[1])]
            rows = rows[rows["_where"] == "ok"].sort_values("dt", kind="stable")
            axes.plot(rows["_t"], rows["_v"], **style, label=plain(_series_label(*key)))
            for end in {rows.index[0], rows.index[-1]} if len(rows) else ():
                axes.annotate(f"{rows.at[end, 'dt']:g}", (rows.at[end, "_t"], rows.at[end, "_v"]),
                              textcoords="offset points", xytext=(3, 3), fontsize=6.5,
                              color=style["color"])
        if len(front):
            axes.step(front["wall_time_s"].map(float_or_nan), front[y].map(float_or_nan),
                      where="post", color="black", alpha=0.3, linewidth=4.0, zorder=1.5,
                      solid_capstyle="round", label="Pareto front")
        edge_handles = _edge_points(axes, frame, colours)
        _set_work_precision_limits(axes, frame)
        axes.set_xlabel("wall time, s (median over repetitions)")
        axes.set_ylabel(Y_LABELS[y])
        axes.set_title(plain(title))
        handles, labels = axes.get_legend_handles_labels()
        figure.legend(handles + edge_handles, labels + [h.get_label() for h in edge_handles],
                      loc="outside lower center", ncols=2, frameon=False)
    counts = Counter(frame.loc[frame["_where"] != "ok", "_label"])
    front_text = ", ".join(f"{_series_label(r.adapter, r.method)} (dt {r.dt:g} s)"
                           for r in front.itertuples()) or "none"
    off = ", ".join(f"{label} {count}" for label, count in sorted(counts.items())) or "none"
    caption = (f"{Y_LABELS[y][0].upper()}{Y_LABELS[y][1:]} against wall time for scenario "
               f"{scenario}, log–log. Each line is one engine · method over its step sizes, "
               "with the smallest and largest dt (s) written at its ends. The grey step line is "
               "the Pareto front: no other ok case is both faster and lower. Cases that did not "
               "end ok are drawn at their wall time in the shaded top band and marked by status; "
               "cases without a wall time sit in the left band.")
    alt = (f"Work-precision diagram, {scenario}, {y}: {len(frame)} cases of {len(series)} "
           f"engine/method combinations, {int((frame['_where'] == 'ok').sum())} drawn as points. "
           f"Pareto front: {front_text}. Off the chart: {off}.")
    return render(figure, title, caption, alt)


def _edge_points(axes, frame: pd.DataFrame, colours: dict) -> list[Line2D]:
    """Draw the cases placed at an edge (top, bottom, left bands), one group per label with the
    SVG id ``edge-<label>``; return legend handles for the labels drawn."""
    handles = []
    left = frame[frame["_where"] == "left"]
    left_y = dict(zip(left.index, 1.0 - _BAND / 2 - np.arange(len(left))
                      * min(_BAND / 2, (1.0 - 2 * _BAND) / max(len(left), 1))))
    for label in sorted(set(frame.loc[frame["_where"] != "ok", "_label"])):
        rows = frame[(frame["_where"] != "ok") & (frame["_label"] == label)]
        colour = [colours[(a, m)] for a, m in zip(rows["adapter"], rows["method"])]
        marker = EDGE_MARKERS.get(label, "o")
        for where, transform, x, y in (
                ("top", axes.get_xaxis_transform(), rows["_t"], 1.0 - _BAND / 2),
                ("bottom", axes.get_xaxis_transform(), rows["_t"], _BAND / 2),
                ("left", axes.transAxes, _BAND / 2, rows.index.map(left_y.get))):
            chosen = (rows["_where"] == where).to_numpy()
            if not chosen.any():
                continue
            xs = np.broadcast_to(np.asarray(x, dtype=float), chosen.shape)[chosen]
            ys = np.broadcast_to(np.asarray(y, dtype=float), chosen.shape)[chosen]
            axes.scatter(xs, ys, c=[c for c, k in zip(colour, chosen) if k], marker=marker,
                         s=36, edgecolors="black", linewidths=0.6, transform=transform,
                         clip_on=False, zorder=4, gid=f"edge-{label}")
        handles.append(Line2D([], [], linestyle="none", marker=marker, markerfacecolor="white",
                              markeredgecolor="black", label=plain(f"{label} ({len(rows)})")))
    return handles


def _set_work_precision_limits(axes, frame: pd.DataFrame) -> None:
    """Limits that leave the edge bands free for the points drawn there, and shade the bands."""
    timed = frame.loc[frame["_where"] != "left", "_t"]
    values = frame.loc[frame["_where"] == "ok", "_v"]
    where = set(frame["_where"])
    x = np.log10(timed.to_numpy(dtype=float)) if len(timed) else np.array([-4.0, 0.0])
    v = np.log10(values.to_numpy(dtype=float)) if len(values) else np.array([-12.0, 0.0])
    x_start = 1.5 * _BAND if "left" in where else 0.03
    y_start = 1.5 * _BAND if "bottom" in where else 0.04
    y_stop = 1.0 - 1.5 * _BAND if "top" in where else 0.96
    axes.set_xlim(*_log_limits(x.min(), x.max(), x_start, 0.97))
    axes.set_ylim(*_log_limits(v.min(), v.max(), y_start, y_stop))
    bands = {"top": ((0.0, 1.0 - _BAND), 1.0, _BAND, "not ok / no value"),
             "bottom": ((0.0, 0.0), 1.0, _BAND, "exactly 0"),
             "left": ((0.0, 0.0), _BAND, 1.0, "no wall time")}
    for name, (corner, width, height, text) in bands.items():
        if name not in where:
            continue
        axes.add_patch(Rectangle(corner, width, height, transform=axes.transAxes,
                                 facecolor="#EEEEEE", edgecolor="none", zorder=0.5))
        vertical = name == "left"
        axes.text(corner[0] + (width / 2 if vertical else 0.995),
                  corner[1] + (0.5 if vertical else height / 2), text,
                  transform=axes.transAxes, fontsize=6.5, color="#555555",
                  ha="center" if vertical else "right", va="center",
                  rotation=90 if vertical else 0, zorder=0.6)


def _cells(frame: pd.DataFrame, rows: list, columns: list, accuracy: float) -> np.ndarray:
    """Outcome index (into OUTCOME_COLOURS) per (row, column), −1 where no case ran.

    Of several cases in one cell (duration overrides), the one with the longest ``t_end``
    counts (ties: the last case id).
    """
    codes = list(OUTCOME_COLOURS)
    grid = np.full((len(rows), len(columns)), -1)
    order = [name for name in ("t_end", "case_id") if name in frame.columns]
    ordered = frame.sort_values(order, kind="stable") if order else frame
    row_index = {key: i for i, key in enumerate(rows)}
    column_index = {dt: j for j, dt in enumerate(columns)}
    for _, case in ordered.iterrows():
        grid[row_index[(case["adapter"], case["method"])], column_index[case["dt"]]] = \
            codes.index(outcome(case, accuracy))
    return grid


def stability_map(cases: pd.DataFrame, sweeps: pd.DataFrame, scenario: str,
                  accuracy: float) -> Figure:
    """Outcome of every case of a scenario, methods × step sizes, with the stability sweep.

    Cells are coloured and lettered by :func:`~mbh._harness.report.style.outcome` with ``accuracy``
    (rad or m on the main output); white cells were not run.  The largest stable dt the sweep
    found for a method is outlined in bold (or marked ◆ between columns when the sweep's step is
    not a column) and written at the row's right end.

    Parameters
    ----------
    cases : DataFrame
        Case rows (scenario, adapter, method, dt, status, main_output_error, accurate).
    sweeps : DataFrame
        Sweep rows (scenario, adapter, method, largest_stable_dt); may be empty.
    scenario : str
    accuracy : float
        Threshold on the main output's error, rad or m.
    """
    title = f"{scenario}: outcome by method and step size"
    frame = _scenario_rows(cases, scenario, ("adapter", "method", "dt", "status"),
                           "stability_map cases")
    sweep = _scenario_rows(sweeps, scenario, ("adapter", "method", "largest_stable_dt"),
                           "stability_map sweeps")
    if frame.empty and sweep.empty:
        return no_data(title, f"no cases or sweeps of scenario {scenario}")
    rows = sorted(set(zip(frame["adapter"], frame["method"]))
                  | set(zip(sweep["adapter"], sweep["method"])))
    columns = sorted(set(frame["dt"].astype(float)))
    grid = _cells(frame, rows, columns, accuracy)
    codes = list(OUTCOME_COLOURS)
    with apply_style():
        figure = new_figure(6.4, 1.9 + 0.24 * len(rows))
        axes = figure.add_subplot()
        cmap = ListedColormap(["#FFFFFF", *OUTCOME_COLOURS.values()])
        norm = BoundaryNorm(np.arange(len(codes) + 2) - 1.5, cmap.N)
        if columns:
            axes.pcolormesh(np.arange(len(columns) + 1) - 0.5, np.arange(len(rows) + 1) - 0.5,
                            grid, cmap=cmap, norm=norm, edgecolors="white", linewidth=0.8)
        for (i, j), code in np.ndenumerate(grid):
            if code >= 0:
                axes.text(j, i, OUTCOME_LETTERS[codes[code]], ha="center", va="center",
                          fontsize=7, color="black")
        stable = _mark_sweeps(axes, sweep, rows, columns)
        axes.set_xlim(-0.5, max(len(columns), 1) - 0.5)
        axes.set_ylim(len(rows) - 0.5, -0.5)
        axes.set_xticks(range(len(columns)), [f"{dt:g}" for dt in columns])
        axes.set_yticks(range(len(rows)), [plain(_series_label(*key)) for key in rows])
        axes.tick_params(axis="x", labelrotation=45)
        axes.grid(False)
        axes.set_xlabel("step size dt, s")
        if len(sweep):
            right = axes.secondary_yaxis("right")
            right.set_yticks(range(len(rows)), [stable.get(key, "") for key in rows])
            right.tick_params(length=0)
            right.set_ylabel("largest stable dt (sweep)", fontsize=7.5)
        axes.set_title(plain(title))
        present = sorted({codes[c] for c in grid.flat if c >= 0}, key=codes.index)
        handles = [Patch(facecolor=OUTCOME_COLOURS[name], edgecolor="#888888",
                         label=f"{OUTCOME_LETTERS[name]} {name}") for name in present]
        if (grid < 0).any():
            handles.append(Patch(facecolor="white", edgecolor="#888888", label="not run"))
        if len(sweep):
            handles.append(Patch(facecolor="none", edgecolor="black", linewidth=2.0,
                                 label="largest stable dt (sweep)"))
        figure.legend(handles=handles, loc="outside lower center", ncols=4, frameon=False)
    counts = Counter(codes[c] for c in grid.flat if c >= 0)
    caption = (f"Outcome of every case of {scenario}: one row per engine · method, one column "
               f"per step size. A: ok and main-output error ≤ {accuracy:g} (rad or m); "
               "I: ok but less accurate; ?: ok without a reference to judge it; D, F, C, T, U: "
               "diverged, failed, crashed, timed out, unsupported. The bold outline (◆ between "
               "columns) is the largest step the stability sweep found stable, also written on "
               "the right.")
    alt = (f"Stability map, {scenario}: {len(rows)} engine/method rows × {len(columns)} step "
           f"sizes; outcomes " + (", ".join(f"{k} {v}" for k, v in sorted(counts.items()))
                                  or "none") + "; largest stable dt: "
           + (", ".join(f"{_series_label(*k)} {v}" for k, v in sorted(stable.items())) or "none")
           + ".")
    return render(figure, title, caption, alt)


def _mark_sweeps(axes, sweep: pd.DataFrame, rows: list, columns: list) -> dict:
    """Outline (or mark) each method's largest stable dt; return its text per row key."""
    stable = {}
    for case in sweep.itertuples():
        i = rows.index((case.adapter, case.method))
        dt = float_or_nan(case.largest_stable_dt)
        if not math.isfinite(dt):
            stable[(case.adapter, case.method)] = "none stable"
            continue
        stable[(case.adapter, case.method)] = f"{dt:.3g} s"
        match = [j for j, column in enumerate(columns) if abs(column - dt) <= 1e-9 * dt]
        if match:
            axes.add_patch(Rectangle((match[0] - 0.5, i - 0.5), 1, 1, facecolor="none",
                                     edgecolor="black", linewidth=2.2, zorder=3,
                                     gid="sweep-stable"))
        elif columns:
            x = np.interp(math.log(dt), np.log(columns), np.arange(len(columns)),
                          left=-0.4, right=len(columns) - 0.6)
            axes.plot([x], [i], marker="D", color="black", markersize=6, linestyle="none",
                      zorder=3, gid="sweep-stable")
    return stable


def jacobian_condition(mech: Mechanism, trajectory: Trajectory) -> np.ndarray:
    """Condition number of [independent joint rows; driver row] at every sample, shape (n,).

    The measure of :func:`mbh._harness.neutral.mobility.rank_analysis` (σ_max/σ_min of that system, σ_min the
    min(rows, columns)-th singular value; ∞ where it is zero), with the independent rows chosen
    once, at the first sample (the start's rank), so that a rank lost later shows as a condition
    growing without bound rather than as a change of rows.
    """
    if trajectory.n_samples == 0:
        return np.zeros(0)
    equations = JointEquations(mech, with_driver=True)
    jacobian = equations.jacobian(trajectory.position, trajectory.quaternion)
    joint_rows = jacobian[:, :equations.n_joint_rows]
    independent = independent_rows(joint_rows[0])
    system = np.concatenate([joint_rows[:, independent],
                             jacobian[:, equations.n_joint_rows:]], axis=1)
    singular_values = np.linalg.svd(system, compute_uv=False)
    smallest = singular_values[:, min(system.shape[1:]) - 1]
    with np.errstate(divide="ignore"):
        return np.where(smallest > 0, singular_values[:, 0] / smallest, np.inf)


def _positive(values: np.ndarray) -> np.ndarray:
    """``values`` with non-positive entries as NaN (not drawn on a log axis)."""
    values = np.asarray(values, dtype=float)
    return np.where(values > 0, values, np.nan)


def time_history(mech: Mechanism, trajectory: Trajectory, reference: Trajectory | None,
                 title: str, outputs: tuple[str, ...] | None = None,
                 t_end: float | None = None) -> Figure:
    """One case over time, panels sharing the time axis.

    Panels: each output (the case in colour over the reference in grey); the output errors
    |y − y_ref| (log); the constraint violation (joint gap and orientation residual × lever
    length ℓ, :func:`mbh._harness.measure.metrics.violation_series`, m, log); the energy-balance error
    (:func:`mbh._harness.measure.energy.energy_balance`, relative to the reference's energy scale, or in J
    without one; log); the condition number of the reference's constraint Jacobian
    (:func:`jacobian_condition`; the case's own without a reference; log).  A run that did not
    end ok has its failure time marked on every panel.

    Parameters
    ----------
    mech : Mechanism
    trajectory : Trajectory
        The case; its sample times must lie on the reference grid.
    reference : Trajectory or None
    title : str
    outputs : tuple of str, optional
        Outputs to draw (default: all of the mechanism's).
    t_end : float, optional
        End of the time axis, s (default: the case's last sample if it ended ok, else the
        mechanism's duration).

    Raises
    ------
    ValueError
        When a sample time is not on the reference grid, or an output is unknown.
    """
    names = tuple(o.name for o in mech.outputs) if outputs is None else tuple(outputs)
    unknown = [name for name in names if name not in {o.name for o in mech.outputs}]
    if unknown:
        raise ValueError(f"time_history: {mech.name} has no output {', '.join(unknown)} "
                         f"(outputs: {', '.join(o.name for o in mech.outputs)})")
    if t_end is None:
        ended = trajectory.status == CaseStatus.OK and trajectory.n_samples
        t_end = float(trajectory.times[-1]) if ended else mech.duration
    if reference is not None:
        last = float(trajectory.times[-1]) if trajectory.n_samples else 0.0
        keep = reference.times <= max(t_end, last) + 1e-9
        reference = Trajectory(reference.times[keep], reference.position[keep],
                               reference.quaternion[keep], reference.velocity[keep],
                               reference.angular_velocity[keep])
        index = reference_indices(reference, trajectory.times)
    times = trajectory.times
    with apply_style():
        figure = new_figure(6.4, 1.45 * (len(names) + 4) + 0.4)
        panels = figure.subplots(len(names) + 4, 1, sharex=True)
        colour = series_style(0)["color"]
        for axes, name in zip(panels, names):
            unit = OUTPUT_UNITS[mech.output(name).kind]
            if reference is not None:
                axes.plot(reference.times, output_series(mech, reference, name),
                          color=REFERENCE_COLOUR, linewidth=2.6, label="reference")
            axes.plot(times, output_series(mech, trajectory, name), color=colour,
                      linewidth=1.1, label="case")
            axes.set_ylabel(plain(f"{name}, {unit}"))
        panels[0].legend(loc="best", frameon=False)
        error_panel, violation_panel, energy_panel, condition_panel = panels[len(names):]
        _error_panel(error_panel, mech, trajectory, reference, names,
                     None if reference is None else index)
        series = violation_series(mech, trajectory)
        lever = lever_length(mech)
        violation_panel.plot(times, _positive(series["joint_gap_m"]), color=colour,
                             label="joint gap")
        if np.any(series["orientation_rad"] > 0):
            violation_panel.plot(times, _positive(lever * series["orientation_rad"]),
                                 color=series_style(1)["color"],
                                 label=f"orientation residual × ℓ (ℓ = {lever:.3g} m)")
        violation_panel.set_ylabel("violation, m")
        violation_panel.legend(loc="best", frameon=False)
        balance = np.abs(energy_balance(mech, trajectory, reference))
        scale = None if reference is None else energy_scale(mech, reference)
        energy_panel.plot(times, _positive(balance if scale is None else balance / scale),
                          color=colour)
        energy_panel.set_ylabel("|energy error| / scale" if scale else "|energy error|, J")
        source = trajectory if reference is None else reference
        condition_panel.plot(source.times, jacobian_condition(mech, source),
                             color=REFERENCE_COLOUR if reference is not None else colour)
        condition_panel.set_ylabel("Jacobian condition" + ("" if reference is not None
                                                          else " (case)"))
        for axes in panels[len(names):]:
            axes.set_yscale("log")
        for axes in panels:
            axes.set_xlim(0.0, t_end)
        panels[-1].set_xlabel("time, s")
        _mark_failure(panels, trajectory)
        panels[0].set_title(plain(title))
    failure = ("" if trajectory.status == CaseStatus.OK else
               f" The run ended {trajectory.status} at t = {_failure_time(trajectory):.4g} s "
               f"(dashed line): {trajectory.reason}")
    caption = ("Outputs of the case over the reference (grey); the absolute output errors; "
               "the joint-equation violation; the energy-balance error; and the condition number "
               "of the reference's constraint Jacobian [independent joint rows; driver row], "
               "which peaks where the mechanism nears a singular position." + failure)
    alt = (f"Time histories of {title}: {trajectory.n_samples} samples to "
           f"{float(times[-1]) if len(times) else 0.0:.4g} s, status {trajectory.status}; "
           f"outputs {', '.join(names)}.")
    return render(figure, title, caption, alt)


def _error_panel(axes, mech, trajectory, reference, names, index) -> None:
    """|y − y_ref| of every output (log), or a note when there is no reference."""
    if reference is None:
        axes.text(0.5, 0.5, "no reference: no error", transform=axes.transAxes, ha="center",
                  va="center", color="#555555")
        axes.set_ylabel("|error|")
        return
    for k, name in enumerate(names):
        error = np.abs(output_series(mech, trajectory, name)
                       - output_series(mech, reference, name)[index])
        unit = OUTPUT_UNITS[mech.output(name).kind]
        axes.plot(trajectory.times, _positive(error), color=series_style(k)["color"],
                  label=plain(f"{name}, {unit}"))
    axes.set_ylabel("|error|")
    axes.legend(loc="best", frameon=False)


def _failure_time(trajectory: Trajectory) -> float:
    if trajectory.failure_time is not None:
        return float(trajectory.failure_time)
    return float(trajectory.times[-1]) if trajectory.n_samples else 0.0


def _mark_failure(panels, trajectory: Trajectory) -> None:
    """A dashed line at the failure time on every panel, labelled with the status on the top."""
    if trajectory.status == CaseStatus.OK:
        return
    t = _failure_time(trajectory)
    for axes in panels:
        axes.axvline(t, color=_FAILURE_COLOUR, linestyle="--", linewidth=1.2, gid="failure-time")
    panels[0].annotate(plain(f"{trajectory.status} at {t:.4g} s"), (t, 1.0),
                       xycoords=panels[0].get_xaxis_transform(), xytext=(3, -3),
                       textcoords="offset points", ha="left", va="top", fontsize=7.5,
                       color=_FAILURE_COLOUR,
                       bbox={"facecolor": "white", "edgecolor": "none", "pad": 1.0})
