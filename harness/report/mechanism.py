"""Pictures of a mechanism drawn from stored body states: snapshots at chosen instants and a
self-contained animated SVG, with several engines overlaid on the reference.

Each body is drawn as bars between its joint points (the joint points of :attr:`Mechanism.joints`
in the body frame, carried to the world by the body's pose): two points give one bar, three or
more a closed outline; a body with one joint point gets a bar from that point through its centre of
mass and on by the same length; a body whose joint points all sit at its centre of mass (a slider)
is a small block.  Ground pivots are triangles; a sliding joint on the ground is a dashed guide
line along its axis over the travel the trajectories cover.

Planar mechanisms are drawn in the world x–y plane.  Spatial ones are projected onto the plane of
largest spread (the first two principal axes of every drawn point at every sample, of the reference
when there is one), fixed for the whole figure, so the instants and engines compare directly.

The trajectory keyed :data:`REFERENCE_KEY` is drawn in grey underneath, the others in the palette's
colours in key order.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from xml.sax.saxutils import escape, quoteattr

import numpy as np

from mbh._harness.model.mechanism import GROUND, Mechanism, characteristic_length
from mbh._harness.model.outputs import body_rotations
from mbh._harness.report.style import (PALETTE, REFERENCE_COLOUR, Figure, apply_style, new_figure,
                                  no_data, plain, render)
from mbh._harness.common.status import CaseStatus
from mbh._harness.model.trajectory import Trajectory

#: The key of ``trajectories`` drawn in grey as the reference.
REFERENCE_KEY = "reference"
#: Joint points closer than this fraction of the mechanism's size are one point.
_SAME_POINT = 1e-9
#: Side of a block body (all joint points at the centre of mass), fraction of the mechanism's size.
_BLOCK = 0.04
_SLIDING = ("prismatic", "translational", "cylindrical")


@dataclass(frozen=True)
class _Outline:
    """A body's drawing in its own frame: ``points`` (k, 3), m; ``kind`` bar, polygon or block."""

    body: int
    points: np.ndarray
    kind: str


def _outline(mech: Mechanism, body: int, size: float) -> _Outline:
    """The bars of body ``body`` (see the module notes)."""
    name = mech.bodies[body].name
    points = []
    for joint in mech.joints:
        for side, point in ((joint.body1, joint.point1), (joint.body2, joint.point2)):
            p = np.asarray(point, dtype=float)
            if side == name and all(np.linalg.norm(p - q) > _SAME_POINT * size for q in points):
                points.append(p)
    if all(np.linalg.norm(p) <= _SAME_POINT * size for p in points):
        return _Outline(body, np.zeros((1, 3)), "block")
    if len(points) == 1:
        return _Outline(body, np.array([points[0], -points[0]]), "bar")
    if len(points) == 2:
        return _Outline(body, np.array(points), "bar")
    stacked = np.array(points)
    centred = stacked - stacked.mean(axis=0)
    axes = np.linalg.svd(centred)[2][:2]
    order = np.argsort(np.arctan2(centred @ axes[1], centred @ axes[0]), kind="stable")
    return _Outline(body, stacked[order], "polygon")


def _world(outline: _Outline, trajectory: Trajectory, rotations: np.ndarray,
           samples: np.ndarray) -> np.ndarray:
    """World points of an outline at ``samples``, shape (len(samples), k, 3), m."""
    position = trajectory.position[samples, outline.body]
    rotation = rotations[samples, outline.body]
    return position[:, None, :] + np.einsum("sij,kj->ski", rotation, outline.points)


@dataclass(frozen=True)
class _Scene:
    """What every drawing of one mechanism shares: outlines, ground marks, projection, view."""

    outlines: tuple[_Outline, ...]
    ground_points: np.ndarray      # (g, 3) world, m
    guides: tuple[np.ndarray, ...]  # each (2, 3) world end points of a sliding guide, m
    basis: np.ndarray              # (3, 2) world → drawing plane
    limits: np.ndarray             # [[u_min, u_max], [v_min, v_max]] in the drawing plane, m
    size: float                    # mechanism size, m

    def project(self, points: np.ndarray) -> np.ndarray:
        """Drawing-plane coordinates (..., 2) of world points (..., 3)."""
        return points @ self.basis


def _all_world_points(outlines, trajectory: Trajectory) -> np.ndarray:
    """Every outline point of ``trajectory`` at every sample, shape (m, 3)."""
    if trajectory.n_samples == 0:
        return np.zeros((0, 3))
    rotations = body_rotations(trajectory.quaternion)
    samples = np.arange(trajectory.n_samples)
    return np.concatenate([_world(o, trajectory, rotations, samples).reshape(-1, 3)
                           for o in outlines])


def _basis(mech: Mechanism, points: np.ndarray) -> np.ndarray:
    """World → drawing-plane projection (3, 2): x–y for planar mechanisms, else the first two
    principal axes of ``points``, each signed so that its largest component is positive."""
    if mech.planar or len(points) < 3:
        return np.eye(3)[:, :2]
    axes = np.linalg.svd(points - points.mean(axis=0), full_matrices=False)[2][:2].T
    signs = np.sign(axes[np.argmax(np.abs(axes), axis=0), [0, 1]])
    return axes * signs


def _guide(mech: Mechanism, joint, trajectories: dict[str, Trajectory]) -> np.ndarray:
    """End points (2, 3) of the guide line of a sliding joint on the ground, over the travel of
    the moving side's joint point in every trajectory."""
    on_ground_first = joint.body1 == GROUND
    origin = np.asarray(joint.point1 if on_ground_first else joint.point2, dtype=float)
    axis = np.asarray(joint.axis1 if on_ground_first else joint.axis2, dtype=float)
    moving = mech.body_index(joint.body2 if on_ground_first else joint.body1)
    local = np.asarray(joint.point2 if on_ground_first else joint.point1, dtype=float)
    travel = [0.0]
    for trajectory in trajectories.values():
        if trajectory.n_samples:
            rotation = body_rotations(trajectory.quaternion[:, moving])
            world = trajectory.position[:, moving] + rotation @ local
            travel.extend(((world - origin) @ axis).tolist())
    margin = 0.1 * characteristic_length(mech)
    return origin + np.outer([min(travel) - margin, max(travel) + margin], axis)


def _scene(mech: Mechanism, trajectories: dict[str, Trajectory]) -> _Scene:
    size = characteristic_length(mech) or 1.0
    outlines = tuple(_outline(mech, b, size) for b in range(len(mech.bodies)))
    ground = [np.asarray(j.point1 if j.body1 == GROUND else j.point2, dtype=float)
              for j in mech.joints if GROUND in (j.body1, j.body2) and j.type not in _SLIDING]
    guides = tuple(_guide(mech, j, trajectories) for j in mech.joints
                   if GROUND in (j.body1, j.body2) and j.type in _SLIDING)
    view = ([trajectories[REFERENCE_KEY]] if REFERENCE_KEY in trajectories
            else list(trajectories.values()))
    points = np.concatenate([_all_world_points(outlines, t) for t in view]
                            + [np.array(ground).reshape(-1, 3)])
    points = points[np.all(np.isfinite(points), axis=1)]
    basis = _basis(mech, points)
    planar = points @ basis if len(points) else np.zeros((1, 2))
    low, high = planar.min(axis=0), planar.max(axis=0)
    pad = 0.08 * max(float(np.max(high - low)), size)
    limits = np.stack([low - pad, high + pad], axis=1)
    return _Scene(outlines, np.array(ground).reshape(-1, 3), guides, basis, limits, size)


def _ordered(trajectories: dict[str, Trajectory]) -> list[tuple[str, Trajectory, str]]:
    """(key, trajectory, colour): the reference first in grey, then the others in key order of
    the dict, in the palette's colours."""
    others = [k for k in trajectories if k != REFERENCE_KEY]
    ordered = [(k, trajectories[k], PALETTE[i % len(PALETTE)]) for i, k in enumerate(others)]
    if REFERENCE_KEY in trajectories:
        ordered.insert(0, (REFERENCE_KEY, trajectories[REFERENCE_KEY], REFERENCE_COLOUR))
    return ordered


def _sample_at(trajectory: Trajectory, t: float) -> int | None:
    """Index of the sample at time ``t`` (s; nearest, within half a sample spacing), or None when
    the trajectory has no sample there (it ended before)."""
    if trajectory.n_samples == 0:
        return None
    index = int(np.argmin(np.abs(trajectory.times - t)))
    spacing = float(np.median(np.diff(trajectory.times))) if trajectory.n_samples > 1 else 0.0
    return index if abs(trajectory.times[index] - t) <= max(0.5 * spacing, 1e-9) else None


def _ending(trajectory: Trajectory, end: float) -> str:
    """" (diverged at 0.43 s)" for a run that did not end ok, " (to 2 s)" for an ok run shorter
    than ``end`` (s), else ""."""
    last = float(trajectory.times[-1]) if trajectory.n_samples else 0.0
    if trajectory.status == CaseStatus.OK:
        return f" (to {last:.3g} s)" if last < end - 1e-9 else ""
    stop = trajectory.failure_time if trajectory.failure_time is not None else last
    return f" ({trajectory.status} at {stop:.3g} s)"


def _latest_end(trajectories: dict[str, Trajectory]) -> float:
    """The latest last sample time of ``trajectories``, s (0 without samples)."""
    return max((float(t.times[-1]) for t in trajectories.values() if t.n_samples), default=0.0)


def _at(trajectory: Trajectory, index: int) -> Trajectory:
    """The one-sample trajectory of sample ``index``."""
    keep = slice(index, index + 1)
    return Trajectory(trajectory.times[keep], trajectory.position[keep],
                      trajectory.quaternion[keep], trajectory.velocity[keep],
                      trajectory.angular_velocity[keep])


def _pose_points(scene: _Scene, trajectory: Trajectory, index: int) -> list[np.ndarray]:
    """World points (k, 3) of every outline at sample ``index``, m."""
    sample = _at(trajectory, index)
    rotations = body_rotations(sample.quaternion)
    return [_world(o, sample, rotations, np.zeros(1, dtype=int))[0] for o in scene.outlines]


def mechanism_snapshots(mech: Mechanism, trajectories: dict[str, Trajectory],
                        times: list[float]) -> Figure:
    """The mechanism at each of ``times`` (s), one panel per instant, engines overlaid.

    Each panel gives the largest distance (3-D, m) of an engine's drawn points from the
    reference's at that instant, so that where engines drift apart is read as a number too.  An
    engine whose run ended before an instant is missing from that panel (its legend entry says
    when it ended).
    """
    title = f"{mech.name}: the mechanism at {len(times)} instants"
    if not trajectories or not times:
        return no_data(title, "no trajectories or no instants")
    scene = _scene(mech, trajectories)
    ordered = _ordered(trajectories)
    end = _latest_end(trajectories)
    columns = min(len(times), 2)
    rows = math.ceil(len(times) / columns)
    span = scene.limits[:, 1] - scene.limits[:, 0]
    panel_width = 6.4 / columns
    drifts = []
    with apply_style():
        figure = new_figure(6.4, rows * panel_width * min(span[1] / span[0], 1.5) + 0.9)
        panels = np.atleast_1d(figure.subplots(rows, columns, squeeze=False)).ravel()
        for axes, t in zip(panels, times):
            drift = _draw_instant(axes, scene, ordered, float(t))
            drifts.append(drift)
            axes.set_xlim(*scene.limits[0])
            axes.set_ylim(*scene.limits[1])
            axes.set_aspect("equal")
            axes.tick_params(labelsize=6.5)
            text = f"t = {float(t):.3g} s"
            if drift is not None:
                text += f"\nlargest drift {drift[1]:.2g} m ({drift[0]})"
            axes.set_title(plain(text), fontsize=8)
        for axes in panels[len(times):]:
            axes.set_axis_off()
        labels = ("x, m", "y, m") if mech.planar else ("projection 1, m", "projection 2, m")
        for axes in panels[:len(times)]:
            axes.set_xlabel(labels[0], fontsize=7)
            axes.set_ylabel(labels[1], fontsize=7)
        handles = [panels[0].plot([], [], color=colour, linewidth=4.0 if key == REFERENCE_KEY
                                  else 1.6, label=plain(key + _ending(trajectory, end)))[0]
                   for key, trajectory, colour in ordered]
        figure.legend(handles=handles, loc="outside lower center", ncols=2, frameon=False)
    plane = ("the x–y plane" if mech.planar else
             "the plane of largest spread (axes " + ", ".join(
                 "(" + ", ".join(f"{c:.2f}" for c in axis) + ")" for axis in scene.basis.T)
             + " in world coordinates)")
    caption = (f"{mech.name} drawn from the stored body states at {len(times)} instants, in "
               f"{plane}: bodies as bars between their joint points, ground pivots as "
               "triangles. The reference is grey underneath; each engine has its own colour. "
               "The panel title gives the largest distance of an engine's joint points from the "
               "reference's.")
    worst = [d for d in drifts if d is not None]
    alt = (f"{mech.name} at t = " + ", ".join(f"{float(t):.3g}" for t in times) + " s; "
           + ", ".join(key + _ending(traj, end) for key, traj, _ in ordered)
           + (f"; largest drift from the reference {max(d[1] for d in worst):.2g} m"
              if worst else "") + ".")
    return render(figure, title, caption, alt)


def _draw_instant(axes, scene: _Scene, ordered, t: float) -> tuple[str, float] | None:
    """Draw every trajectory at time ``t``; return (engine, largest drift from the reference, m)
    or None without a reference there."""
    for guide in scene.guides:
        u, v = scene.project(guide).T
        axes.plot(u, v, color="#555555", linestyle="--", linewidth=0.8, zorder=1)
    if len(scene.ground_points):
        u, v = scene.project(scene.ground_points).T
        axes.plot(u, v, linestyle="none", marker="^", markersize=8, color="#333333", zorder=5)
    reference_points, drift = None, None
    for key, trajectory, colour in ordered:
        index = _sample_at(trajectory, t)
        if index is None:
            continue
        is_reference = key == REFERENCE_KEY
        poses = _pose_points(scene, trajectory, index)
        for outline, world in zip(scene.outlines, poses):
            if outline.kind == "polygon":
                world = np.vstack([world, world[:1]])
            u, v = scene.project(world).T
            block = outline.kind == "block"
            axes.plot(u, v, color=colour, linewidth=4.0 if is_reference else 1.6,
                      alpha=0.55 if is_reference else 0.95, marker="s" if block else "o",
                      markersize=7 if block else (4 if is_reference else 2.5),
                      solid_capstyle="round", zorder=2 if is_reference else 3)
        points = np.concatenate(poses)
        if is_reference:
            reference_points = points
        elif reference_points is not None:
            gap = float(np.max(np.linalg.norm(points - reference_points, axis=1)))
            if drift is None or gap > drift[1]:
                drift = (key, gap)
    return drift


#: Width of the animation's drawing area, SVG user units.
_WIDTH = 640.0


def _svg_path(points: np.ndarray, kind: str, half_block: float) -> str:
    """SVG path data of one outline (points (k, 2) in SVG units); same commands every frame, so
    frames interpolate."""
    if kind == "block":
        x, y = points[0]
        h = half_block
        return f"M{x - h:.1f} {y - h:.1f}H{x + h:.1f}V{y + h:.1f}H{x - h:.1f}Z"
    body = "L".join(f"{x:.1f} {y:.1f}" for x, y in points)
    return "M" + body + ("Z" if kind == "polygon" else "")


def mechanism_animation(mech: Mechanism, trajectories: dict[str, Trajectory],
                        frames: int = 60) -> str:
    """A self-contained animated SVG of the mechanism, engines overlaid on the reference.

    ``frames`` instants evenly spaced from 0 to the latest end of the trajectories; each body is a
    ``<path>`` whose shape is animated with SMIL (``<animate attributeName="d">``, looping, in
    real time but at least 2 s); an engine whose run ended is hidden from then on.  A bar at the
    bottom shows the time.  No scripts, no external references; about 0.4 kB per body, engine and
    ten frames.

    Returns
    -------
    str
        ``<svg>`` text with a ``viewBox`` and no fixed size.

    Raises
    ------
    ValueError
        For ``frames`` < 2.
    """
    if frames < 2:
        raise ValueError(f"mechanism_animation: frames must be ≥ 2, got {frames}")
    ordered = [(k, t, c) for k, t, c in _ordered(trajectories) if t.n_samples]
    end = _latest_end(trajectories)
    scene = _scene(mech, trajectories) if ordered else None
    label = f"{mech.name}: animation of " + (", ".join(k + _ending(t, end) for k, t, _ in ordered)
                                             or "no trajectories")
    if scene is None or end <= 0.0:
        return (f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {_WIDTH:.0f} 60" '
                f'role="img" aria-label={quoteattr(label)}><title>{escape(label)}</title>'
                f'<text x="{_WIDTH / 2:.0f}" y="35" text-anchor="middle" font-size="16" '
                'font-family="sans-serif">no data: no samples to animate</text></svg>')
    (u0, u1), (v0, v1) = scene.limits
    scale = _WIDTH / (u1 - u0)
    height = (v1 - v0) * scale
    legend_top = height + 52.0
    total = legend_top + 22.0 * math.ceil(len(ordered) / 2) + 6.0
    duration = max(end, 2.0)
    instants = np.linspace(0.0, end, frames)

    def to_svg(points: np.ndarray) -> np.ndarray:
        planar = scene.project(points)
        return np.column_stack([(planar[:, 0] - u0) * scale, (v1 - planar[:, 1]) * scale])

    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {_WIDTH:.0f} {total:.0f}" '
             f'role="img" aria-label={quoteattr(label)}>', f"<title>{escape(label)}</title>",
             f'<rect width="{_WIDTH:.0f}" height="{total:.0f}" fill="#ffffff"/>']
    for guide in scene.guides:
        (x0, y0), (x1, y1) = to_svg(guide)
        parts.append(f'<path d="M{x0:.1f} {y0:.1f}L{x1:.1f} {y1:.1f}" stroke="#555555" '
                     'stroke-dasharray="6 4" fill="none"/>')
    for x, y in to_svg(scene.ground_points) if len(scene.ground_points) else ():
        parts.append(f'<path d="M{x:.1f} {y:.1f}l-7 12h14Z" fill="#333333"/>')
    timing = f'dur="{duration:.3g}s" repeatCount="indefinite"'
    for key, trajectory, colour in ordered:
        samples = [_sample_at(trajectory, t) for t in instants]
        last = max(i for i, s in enumerate(samples) if s is not None) if any(
            s is not None for s in samples) else -1
        filled = [s if s is not None else trajectory.n_samples - 1 for s in samples]
        width = 7.0 if key == REFERENCE_KEY else 3.0
        opacity = 0.55 if key == REFERENCE_KEY else 0.95
        group = [f'<g stroke="{colour}" fill="none" stroke-width="{width}" '
                 f'stroke-opacity="{opacity}" stroke-linecap="round" stroke-linejoin="round">']
        if last < frames - 1:
            cut = (last + 1) / (frames - 1)
            group.append(f'<animate attributeName="visibility" values="visible;hidden" '
                         f'keyTimes="0;{cut:.4f}" calcMode="discrete" {timing}/>')
        poses = [_pose_points(scene, trajectory, s) for s in filled]
        for b, outline in enumerate(scene.outlines):
            shapes = [_svg_path(to_svg(pose[b]), outline.kind, 0.5 * _BLOCK * scene.size * scale)
                      for pose in poses]
            group.append(f'<path d="{shapes[0]}"><animate attributeName="d" '
                         f'values="{";".join(shapes)}" {timing}/></path>')
        group.append("</g>")
        parts.extend(group)
    parts.append(f'<rect x="10" y="{height + 8:.0f}" width="{_WIDTH - 20:.0f}" height="6" '
                 'fill="#eeeeee"/>')
    parts.append(f'<rect x="10" y="{height + 8:.0f}" width="0" height="6" fill="#555555">'
                 f'<animate attributeName="width" values="0;{_WIDTH - 20:.0f}" {timing}/></rect>')
    text = 'font-family="sans-serif" font-size="13" fill="#333333"'
    parts.append(f'<text x="10" y="{height + 28:.0f}" {text}>0 s</text>')
    parts.append(f'<text x="{_WIDTH - 10:.0f}" y="{height + 28:.0f}" text-anchor="end" '
                 f'{text}>{end:.3g} s</text>')
    for i, (key, trajectory, colour) in enumerate(ordered):
        x = 10 + (i % 2) * _WIDTH / 2
        y = legend_top + 22.0 * (i // 2)
        parts.append(f'<path d="M{x:.0f} {y - 4:.0f}h24" stroke="{colour}" stroke-width="5"/>')
        parts.append(f'<text x="{x + 30:.0f}" y="{y:.0f}" {text}>'
                     f'{escape(key + _ending(trajectory, end))}</text>')
    parts.append("</svg>")
    return "\n".join(parts)
