"""The report section "Where methods fail" (issue 13): per hard scene, where each engine and
method stops being trustworthy, read from the stored rows only.

A scene enters the section when its scenario carries the tag ``"hard"`` or the run's stability
sweep covers it.  Per scene the section holds

* the largest stable step of every swept (adapter, method) (:func:`stable_steps_table`), and the
  outcome of every case per step size (:func:`outcomes_table`);
* the conditioning of the reference's joint Jacobian Φ_q over time, σ_r/σ_1 with r the rank at
  the start (:func:`harness.conditioning.conditioning`), with every failed case's failure time marked
  (:func:`conditioning_figure`): a scene whose equations are redundant everywhere (rank r below
  the number of rows at every configuration) is not "singular" everywhere, only where σ_r → 0;
* a short reading generated from the rows (:func:`reading`): which methods pass the
  near-singular positions, which fail there, which engines cannot represent the scene, how the
  largest stable step of explicit integration compares with implicit integration.

Near-singular positions and failures *at* them are defined in :mod:`mbh._harness.neutral.conditioning` (the
same definition labels a failed run's reason).  Only the joint rows count: a dead centre of a slider-crank, where Φ_q keeps its rank and only the
driven coordinate stops determining the others, is not a near-singular position here.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pandas as pd
from matplotlib.lines import Line2D

from mbh._harness.model import scenario as scenarios
from mbh._harness.neutral.conditioning import (SINGULAR_DROP, SINGULAR_WINDOW_S, STOPPED,
                                               Conditioning, conditioning, nearest_passage)
from mbh._harness.model.mechanism import Mechanism
from mbh._harness.store.reference_files import stored_reference
from mbh._harness.report.style import (OUTCOME_COLOURS, REFERENCE_COLOUR, Figure, apply_style,
                                  is_missing, new_figure, outcome, plain, render)
from mbh._harness.report.summary import Table
from mbh._harness.model.scenario import ScenarioError
from mbh._harness.common.status import CaseStatus
from mbh._harness.common.numbers import as_float, float_or_nan

#: Scenario tag that puts a scene into the section.
HARD_TAG = "hard"
#: Characters of a failure reason quoted in the reading.
REASON_LENGTH = 90

#: Integration of each in-house integrator family: implicit families solve for the new state,
#: explicit ones evaluate the right-hand side at known states.  LSODA switches between both.
_INHOUSE_KIND = {
    "euler": "explicit", "symplectic-euler": "explicit", "heun": "explicit", "rk4": "explicit",
    "rkn4": "explicit", "rk5": "explicit", "rk8": "explicit", "rk45": "explicit",
    "dop853": "explicit",
    **{f"ab{k}": "explicit" for k in range(1, 6)},
    **{f"am{k}": "implicit" for k in range(1, 6)},
    **{f"bdf{k}": "implicit" for k in range(1, 5)},
    "bdf": "implicit", "radau": "implicit", "ida": "implicit",
}
#: Integration of the engines' methods in applied (spring) forces, from each adapter's method
#: descriptions (``mbh methods --adapter NAME``).  MuJoCo's ``implicit*`` and ``discrete`` are
#: implicit in velocity-dependent forces only, Bullet steps semi-implicit Euler: neither is
#: implicit in a stiff spring's position dependence, so MuJoCo's are left unclassified and Bullet's
#: count as explicit.
_ENGINE_KIND = {
    "mujoco": {"default": "explicit", "best": "explicit", "euler": "explicit",
               "euler-tight": "explicit", "rk4": "explicit", "rk4-tight": "explicit"},
    "pinocchio": {"default": "explicit", "best": "explicit", "rk4": "explicit",
                  "baumgarte": "explicit", "symplectic-projected": "explicit"},
    "pybullet": {"default": "explicit", "best": "explicit", "substeps": "explicit"},
    "exudyn": {"default": "implicit", "best": "implicit", "newmark": "implicit",
               "trapezoidal": "implicit"},
}


#: The in-house adapter's aliases are both fourth-order Runge–Kutta (explicit); a test checks this
#: against the adapter's own resolution, since a report never asks an adapter.
_INHOUSE_ALIAS_KIND = {"default": "explicit", "best": "explicit"}


def integration_kind(adapter: str, method: str) -> str | None:
    """``"explicit"``, ``"implicit"`` or None (not known) for a method string of an adapter.

    The in-house integrator family is the part of the method name before ``+``; its aliases
    (``default``, ``best``) are in :data:`_INHOUSE_ALIAS_KIND`.
    """
    name = method.partition(":")[0]
    if adapter != "inhouse":
        return _ENGINE_KIND.get(adapter, {}).get(name)
    if name in _INHOUSE_ALIAS_KIND:
        return _INHOUSE_ALIAS_KIND[name]
    return _INHOUSE_KIND.get(name.partition("+")[0])


@dataclass(frozen=True)
class FailureScene:
    """One scene of the section.

    Attributes
    ----------
    scenario : str
    stable_steps : Table
        :func:`stable_steps_table`.
    outcomes : Table
        :func:`outcomes_table`.
    conditioning : Figure or None
        :func:`conditioning_figure`; None for a scene not tagged hard (its reading still
        states the conditioning) or without a verified reference (a note says why).
    reading : tuple of str
        :func:`reading`: sentences.
    """

    scenario: str
    stable_steps: Table
    outcomes: Table
    conditioning: Figure | None
    reading: tuple[str, ...]


def _label(row) -> str:
    return f"{row['adapter']} {row['method']} dt={row['dt']:g}"


def _rows(frame: pd.DataFrame, scenario: str) -> pd.DataFrame:
    if frame is None or frame.empty:
        return pd.DataFrame(columns=["scenario", "adapter", "method"])
    return frame[frame["scenario"] == scenario].reset_index(drop=True)


def _tried_text(tried) -> str:
    """The sweep's runs as "dt status (error), …" (its ``tried`` column: JSON of
    [dt, status, main-output error])."""
    try:
        runs = json.loads(tried) if isinstance(tried, str) else []
    except json.JSONDecodeError:
        return str(tried)
    return ", ".join(f"{dt:.3g} {status}" + ("" if status != CaseStatus.OK
                                             or as_float(error) is None
                                             else f" ({as_float(error):.2g})")
                     for dt, status, error in runs)


def stable_steps_table(sweeps: pd.DataFrame, scenario: str) -> Table:
    """Largest stable step per (adapter, method) of ``scenario`` from the stability sweep."""
    rows = []
    for sweep in _rows(sweeps, scenario).sort_values(["adapter", "method"]).to_dict("records"):
        rows.append((sweep["adapter"], sweep["method"],
                     integration_kind(sweep["adapter"], sweep["method"]) or "—",
                     sweep.get("largest_stable_dt"), sweep.get("criterion"),
                     _tried_text(sweep.get("tried"))))
    return Table(key=f"failmap-stable-{scenario}",
                 caption=f"{scenario}: largest stable step per engine and method (stability sweep)",
                 columns=("adapter", "method", "integration", "largest stable dt (s)",
                          "criterion", "runs: dt s, status (main-output error)"),
                 rows=tuple(rows),
                 note="Bisection over dt = 0.01 s / k: the largest step whose run ends ok and, "
                      "with a verified reference, within the campaign's accuracy; — when no step "
                      "passed.")


def _cell(row, accuracy: float) -> str:
    """A case's outcome as a table cell: accurate/inaccurate with the error, or the status with
    the failure time."""
    kind = outcome(row, accuracy)
    error = row.get("main_output_error")
    if kind in ("accurate", "inaccurate"):
        return f"{kind} ({float(error):.2g})"
    if kind == "unverified":
        return "ok (no reference)"
    if kind in STOPPED and not is_missing(row.get("failure_time")):
        return f"{kind} at {float(row['failure_time']):.4g} s"
    return kind


def outcomes_table(cases: pd.DataFrame, scenario: str, accuracy: float) -> Table:
    """Outcome of every case of ``scenario``: one row per (adapter, method), one column per dt.

    Of several cases in one cell (duration overrides), the longest ``t_end`` is shown.
    """
    frame = _rows(cases, scenario)
    steps = sorted(set(frame["dt"].astype(float))) if len(frame) else []
    cells: dict[tuple, dict[float, str]] = {}
    ordered = frame.sort_values(["t_end", "case_id"], kind="stable") if len(frame) else frame
    for row in ordered.to_dict("records"):
        cells.setdefault((row["adapter"], row["method"]), {})[float(row["dt"])] = \
            _cell(row, accuracy)
    rows = tuple((adapter, method, *(cells[(adapter, method)].get(dt) for dt in steps))
                 for adapter, method in sorted(cells))
    return Table(key=f"failmap-outcomes-{scenario}",
                 caption=f"{scenario}: outcome of every case per step size",
                 columns=("adapter", "method", *(f"dt {dt:g} s" for dt in steps)), rows=rows,
                 note=f"accurate/inaccurate: ok with the main-output error (rad or m) within / "
                      f"beyond {accuracy:g}; a failure with the time it stopped.")


def _stopped(frame: pd.DataFrame) -> pd.DataFrame:
    """Cases that ran and stopped at a known time, by failure time."""
    if frame.empty:
        return frame
    times = frame["failure_time"].map(float_or_nan)
    chosen = frame[frame["status"].isin(STOPPED) & np.isfinite(times)]
    return chosen.assign(_t=times[chosen.index]).sort_values(["_t", "case_id"], kind="stable")


def conditioning_figure(scenario: str, cond: Conditioning, cases: pd.DataFrame) -> Figure:
    """The reference's σ_r/σ_1 over time (log) with every failed case's failure time marked.

    Top panel: the conditioning, near-singular positions marked ▽ and their ±window shaded;
    bottom panel: one line per stopped case (adapter · method · dt) with a marker at its failure
    time, coloured by status.
    """
    title = f"{scenario}: failure times over the reference's conditioning"
    failed = _stopped(cases)
    window = [(t - SINGULAR_WINDOW_S, t + SINGULAR_WINDOW_S) for t in cond.minimum_times]
    with apply_style():
        figure = new_figure(6.4, 2.6 + 0.17 * max(len(failed), 1))
        top, bottom = figure.subplots(2, 1, sharex=True,
                                      height_ratios=(2.2, 0.5 + 0.17 * max(len(failed), 1)))
        top.plot(cond.times, np.where(cond.ratio > 0, cond.ratio, np.nan),
                 color=REFERENCE_COLOUR, linewidth=1.6, label="reference σ_r/σ_1")
        top.axhline(cond.threshold, color="#555555", linestyle=":", linewidth=0.8)
        top.plot(cond.minimum_times, cond.ratio[cond.minima], linestyle="none", marker="v",
                 color="black", label=f"near-singular (≤ {cond.threshold:.2g})")
        top.set_yscale("log")
        top.set_ylabel(f"σ_{cond.rank}/σ_1 of Φ_q")
        for axes in (top, bottom):
            for low, high in window:
                axes.axvspan(low, high, color="#EEEEEE", zorder=0)
        for y, row in enumerate(failed.to_dict("records")):
            colour = OUTCOME_COLOURS[row["status"]]
            top.axvline(row["_t"], color=colour, linewidth=0.8, alpha=0.8, gid="failure-time")
            bottom.plot([row["_t"]], [y], marker="X", color=colour, markeredgecolor="black",
                        markersize=6, linestyle="none", gid="failure-time")
        bottom.set_yticks(range(len(failed)), [plain(_label(r)) for r in failed.to_dict("records")],
                          fontsize=6.5)
        bottom.set_ylim(max(len(failed), 1) - 0.5, -0.5)
        if failed.empty:
            bottom.text(0.5, 0.5, "no case stopped", transform=bottom.transAxes, ha="center",
                        va="center", color="#555555")
        end = max([float(cond.times[-1]) if len(cond.times) else 0.0, *failed["_t"]]) \
            if len(failed) else (float(cond.times[-1]) if len(cond.times) else 1.0)
        bottom.set_xlim(-0.01 * end, end)
        top.margins(y=0.08)
        statuses = sorted(set(failed["status"])) if len(failed) else []
        if statuses:
            bottom.legend(handles=[Line2D([], [], linestyle="none", marker="X",
                                          color=OUTCOME_COLOURS[s], markeredgecolor="black",
                                          label=s) for s in statuses],
                          loc="upper right", frameon=False, fontsize=6.5)
        bottom.set_xlabel("time, s")
        top.legend(loc="lower right", frameon=False)
        top.set_title(plain(title))
    minima = ", ".join(f"{t:.4g} s" for t in cond.minimum_times) or "none"
    caption = (f"The reference's conditioning σ_r/σ_1 of the joint Jacobian Φ_q "
               f"(r = {cond.rank} of {cond.n_rows} rows: the rank at the start), log scale; "
               f"triangles: near-singular positions (local minima ≤ {SINGULAR_DROP:g} × the "
               f"median, {cond.threshold:.2g}; dotted), shaded ±{SINGULAR_WINDOW_S:g} s "
               "around them. Below, every case that stopped (failed, diverged, crashed, timed "
               "out) at its failure time, also drawn as a vertical line above.")
    alt = (f"{title}: near-singular positions at {minima}; {len(failed)} stopped cases: "
           + ("; ".join(f"{_label(r)} {r['status']} at {r['_t']:.4g} s"
                        for r in failed.to_dict("records")) or "none") + ".")
    return render(figure, title, caption, alt)


def _names(pairs) -> str:
    return ", ".join(f"{adapter} {method}" for adapter, method in pairs)


def _passing_sentence(frame: pd.DataFrame, accuracy: float, minima: np.ndarray) -> str:
    passed: dict[tuple, list[tuple[float, float]]] = {}
    first = float(minima[0]) if len(minima) else None
    for row in frame.to_dict("records"):
        if outcome(row, accuracy) == "accurate" and (first is None or row["t_end"] > first):
            passed.setdefault((row["adapter"], row["method"]), []).append(
                (float(row["dt"]), float(row["main_output_error"])))
    what = ("Pass the near-singular positions (ok and within "
            f"{accuracy:g} at some step, running past t = {first:.4g} s)" if first is not None
            else f"Ok and within {accuracy:g} at some step")
    if not passed:
        return f"{what}: none."
    parts = [f"{adapter} {method} (" + ", ".join(f"dt {dt:g}: {error:.2g}"
                                                 for dt, error in sorted(runs, reverse=True)) + ")"
             for (adapter, method), runs in sorted(passed.items())]
    return f"{what}: {'; '.join(parts)}."


def _short(reason, length: int = REASON_LENGTH) -> str:
    """A failure reason on one line, cut to ``length`` characters."""
    text = " ".join(str(reason or "no reason given").split())
    return text if len(text) <= length else text[:length - 1] + "…"


def _failure_sentences(frame: pd.DataFrame, minima: np.ndarray) -> list[str]:
    # Cases of one method that stop alike (same status, time and reason) share one entry.
    groups: dict[tuple, list[float]] = {}
    for row in _stopped(frame).to_dict("records"):
        key = (row["adapter"], row["method"], row["status"], f"{row['_t']:.4g}",
               nearest_passage(row["_t"], minima), _short(row["reason"]))
        groups.setdefault(key, []).append(float(row["dt"]))
    at, elsewhere = [], []
    for (adapter, method, status, time, near, reason), steps in groups.items():
        text = (f"{adapter} {method} dt={', '.join(f'{dt:g}' for dt in sorted(steps))} "
                f"{status} at {time} s")
        if near is not None:
            at.append(f"{text} (passage at {near:.4g} s): “{reason}”")
        else:
            elsewhere.append(f"{text}: “{reason}”")
    sentences = []
    if len(minima):
        sentences.append(f"Fail at a near-singular position (within ±{SINGULAR_WINDOW_S:g} s of "
                         f"one): " + ("; ".join(at) if at else "none") + ".")
    if elsewhere:
        prefix = "Fail away from the near-singular positions" if len(minima) else "Fail"
        sentences.append(f"{prefix}: {'; '.join(elsewhere)}.")
    timed = set(_stopped(frame)["case_id"]) if len(frame) else set()
    untimed = frame[frame["status"].isin(STOPPED) & ~frame["case_id"].isin(timed)]
    if len(untimed):
        sentences.append("Stopped without a failure time: " + "; ".join(
            f"{_label(row)} {row['status']}: “{_short(row['reason'])}”"
            for row in untimed.sort_values("case_id").to_dict("records")) + ".")
    return sentences


def _inaccurate_sentence(frame: pd.DataFrame, accuracy: float) -> str | None:
    """Methods that ran through (ok) at every step they ran but never within ``accuracy``."""
    worst = []
    for (adapter, method), group in frame.groupby(["adapter", "method"], sort=True):
        kinds = [outcome(row, accuracy) for row in group.to_dict("records")]
        if "inaccurate" in kinds and "accurate" not in kinds:
            errors = group.loc[group["status"] == CaseStatus.OK, "main_output_error"].astype(float)
            limit = _limit_note(group)
            worst.append(f"{adapter} {method} (smallest error {errors.min():.2g}"
                         + (f"; {_short(limit)}" if limit else "") + ")")
    if not worst:
        return None
    return (f"Run through but never within {accuracy:g} (ok and inaccurate, reported as such): "
            f"{'; '.join(worst)}.")


#: The start of an adapter's note naming the engine's limit (docs/measurements.md, "Engine
#: settings on hard loops").
LIMIT_NOTE = "engine limit:"


def _limit_note(group: pd.DataFrame) -> str:
    """The first note naming an engine's limit among the rows of ``group`` ('' when none does);
    a row's ``notes`` are stored as a JSON list."""
    for text in group["notes"] if "notes" in group else ():
        try:
            notes = json.loads(text) if isinstance(text, str) else list(text)
        except (TypeError, ValueError):
            continue
        for note in notes:
            if str(note).startswith(LIMIT_NOTE):
                return str(note)
    return ""


def _unsupported_sentence(frame: pd.DataFrame) -> str | None:
    chosen = frame[frame["status"] == CaseStatus.UNSUPPORTED] if len(frame) else frame
    if chosen.empty:
        return None
    reasons = {adapter: str(group["reason"].iloc[0])
               for adapter, group in chosen.groupby("adapter", sort=True)}
    return ("Cannot represent the scene (unsupported): "
            + "; ".join(f"{adapter} ({reason})" for adapter, reason in reasons.items()) + ".")


def _stiffness_sentence(sweep: pd.DataFrame) -> str | None:
    """The largest stable step of explicit against implicit integration (sweep rows)."""
    best: dict[str, tuple[float, str]] = {}
    failing: dict[str, list[str]] = {}
    for row in sweep.to_dict("records"):
        kind = integration_kind(row["adapter"], row["method"])
        if kind is None:
            continue
        dt = row.get("largest_stable_dt")
        name = f"{row['adapter']} {row['method']}"
        if is_missing(dt) or not math.isfinite(float(dt)):
            failing.setdefault(kind, []).append(name)
        elif float(dt) > best.get(kind, (0.0, ""))[0]:
            best[kind] = (float(dt), name)
    if not ({"explicit", "implicit"} <= set(best) | set(failing)):
        return None
    parts = []
    for kind in ("explicit", "implicit"):
        if kind in best:
            parts.append(f"{kind} integration up to {best[kind][0]:.3g} s ({best[kind][1]})")
        else:
            parts.append(f"{kind} integration none stable in the swept range "
                         f"({', '.join(failing[kind])})")
    sentence = "Largest stable step: " + "; ".join(parts) + "."
    if "explicit" in best and "implicit" in best:
        factor = best["implicit"][0] / best["explicit"][0]
        if factor > 1:
            sentence += f" Explicit integration needs steps {factor:.3g}× smaller here."
    elif "implicit" in best:
        sentence += " Only implicit integration is stable here."
    return sentence


def reading(scenario: str, cases: pd.DataFrame, sweeps: pd.DataFrame, accuracy: float,
            cond: Conditioning | None) -> tuple[str, ...]:
    """Sentences on ``scenario`` generated from its case and sweep rows (and the conditioning of
    its reference, when there is one)."""
    frame, sweep = _rows(cases, scenario), _rows(sweeps, scenario)
    minima = cond.minimum_times if cond is not None else np.zeros(0)
    sentences = []
    if cond is None:
        sentences.append("No conditioning of a verified reference to place the failures "
                         "against (the notes at the end of the section say why).")
    elif len(minima):
        sentences.append(
            f"The reference's σ_r/σ_1 (r = {cond.rank} of {cond.n_rows} joint rows) falls to "
            f"≤ {SINGULAR_DROP:g} × its median ({cond.threshold:.2g}) at {len(minima)} "
            f"near-singular position(s) within the run: "
            + ", ".join(f"t = {t:.4g} s ({cond.ratio[i]:.2g})"
                        for t, i in zip(minima, cond.minima)) + ".")
    else:
        sentences.append(
            f"The reference's σ_r/σ_1 (r = {cond.rank} of {cond.n_rows} joint rows) stays above "
            f"{SINGULAR_DROP:g} × its median within the run (between {cond.ratio.min():.2g} and "
            f"{cond.ratio.max():.2g}): the joints "
            "keep their rank (a dead centre, where only the driven coordinate loses control of "
            "the others, does not show in Φ_q).")
    if len(frame):
        sentences.append(_passing_sentence(frame, accuracy, minima))
        sentences += _failure_sentences(frame, minima)
    sentences += [s for s in (_inaccurate_sentence(frame, accuracy) if len(frame) else None,
                              _unsupported_sentence(frame), _stiffness_sentence(sweep)) if s]
    return tuple(sentences)


def _load(name: str) -> Mechanism | None:
    """The scenario as it loads now, or None."""
    try:
        return scenarios.load(name)
    except (ScenarioError, OSError):
        return None


def _conditioning(name: str, mech: Mechanism | None, frame: pd.DataFrame, manifest: dict,
                  omit: Callable[[str], None]) -> Conditioning | None:
    """The conditioning of the reference of scenario ``name`` over the run's span, or None
    (``omit`` says why): the scenario must load, be unchanged since the run and have a verified
    reference."""
    if mech is None:
        omit(f"{name}: the scenario does not load now; no conditioning is drawn.")
        return None
    stored = (manifest.get("scenario_hashes") or {}).get(name)
    if stored != mech.content_hash:
        omit(f"{name}: the scenario file changed since the run (content hash {str(stored)[:12]} "
             f"in the run, {mech.content_hash[:12]} now); no conditioning is drawn.")
        return None
    reference = stored_reference(mech)
    if reference is None:
        omit(f"{name}: no verified reference is stored for it (``mbh reference {name}`` builds "
             f"one); no conditioning is drawn.")
        return None
    return conditioning(mech, reference, float(frame["t_end"].max()) if len(frame) else None)


def section_scenes(cases: pd.DataFrame, sweeps: pd.DataFrame, accuracy: float, manifest: dict,
                   omit: Callable[[str], None]) -> list[FailureScene]:
    """The section's scenes (tagged hard, or swept), in name order; empty when there are none.

    Parameters
    ----------
    cases, sweeps : DataFrame
        The run's case and sweep rows (:meth:`mbh._harness.store.runs.RunStore.cases`, ``sweeps``).
    accuracy : float
        The campaign's threshold on the main output, rad or m.
    manifest : dict
        The run's manifest (scenario content hashes).
    omit : callable
        ``omit(why)``: records what the section leaves out.
    """
    swept = set(sweeps["scenario"]) if len(sweeps) else set()
    names = sorted((set(cases["scenario"].dropna()) if len(cases) else set()) | swept)
    scenes = []
    for name in names:
        mech = _load(name)
        hard = mech is not None and HARD_TAG in mech.tags
        if not (hard or name in swept):
            continue
        frame = _rows(cases, name)
        cond = _conditioning(name, mech, frame, manifest, omit)
        figure = conditioning_figure(name, cond, frame) if cond is not None and hard else None
        scenes.append(FailureScene(name, stable_steps_table(sweeps, name),
                                   outcomes_table(cases, name, accuracy), figure,
                                   reading(name, cases, sweeps, accuracy, cond)))
    return scenes
