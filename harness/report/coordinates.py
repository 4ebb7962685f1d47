"""The in-house formulation in absolute and in joint coordinates side by side, per scene, with
the engines beside them: cost per step, error at an equal step, largest step that ends ``ok``.

The absolute model has 3 coordinates per planar body and 7 per spatial body with the joints'
equations; the joint model has the spanning tree's joint coordinates and only the cut joints'
closure equations (docs/methods.md, "Joint coordinates").  Which model a case ran is read from its
``model_notes`` (the in-house adapter's :meth:`method_model_size` writes ``"absolute coordinates:
…"`` or ``"joint coordinates: …"``), so ``coords=auto`` cases land on the side they took.  An
in-house method enters the table when the run has it in both coordinates (the same method name
once its ``coords`` option is left out); the engines' methods are listed beside them as they ran.
"""

from __future__ import annotations

import pandas as pd

from mbh._harness.common.status import CaseStatus
from mbh._harness.report.summary import INHOUSE, Table, _plain, slug

#: The two in-house models, in the order of the table.
MODELS = ("absolute", "joint")


def model_of(notes) -> str | None:
    """``"absolute"`` or ``"joint"`` from an in-house case's ``model_notes``; None otherwise."""
    if not isinstance(notes, str):
        return None
    return next((model for model in MODELS if notes.startswith(f"{model} coordinates")), None)


def without_coords(method: str) -> str:
    """``method`` with its ``coords`` option left out (``"ab5+baumgarte:coords=joint"`` →
    ``"ab5+baumgarte"``), the other options kept in their order."""
    name, _, options = method.partition(":")
    kept = [part for part in options.split(",")
            if part.strip() and part.partition("=")[0].strip() != "coords"]
    return name + (":" + ",".join(kept) if kept else "")


def coordinates_table(cases: pd.DataFrame, scenario: str) -> Table | None:
    """Per in-house method run in both coordinates on ``scenario``, a row for each model, then a
    row per engine method; None when no in-house method ran in both.

    Columns: the model's coordinates and constraint (closure) equations; the median wall time per
    step of the row's ``ok`` cases (µs); the status and main-output error (rad or m) of its case
    at the *equal step*, the smallest step every in-house row ran; the largest step of the run
    whose case ended ``ok`` (s; the stability sweep, where a campaign has one, bisects it).
    """
    mine = cases[cases["scenario"] == scenario]
    own = mine[mine["adapter"] == INHOUSE]
    model = own["model_notes"].map(model_of)
    base = own["method"].map(without_coords)
    paired = sorted(b for b in base.unique() if set(MODELS) <= set(model[base == b]))
    if not paired:
        return None
    groups = [(f"{INHOUSE} {side}", method, group)
              for b in paired for side in MODELS
              for method, group in own[(base == b) & (model == side)].groupby("method", sort=True)]
    steps = set.intersection(*(set(group["dt"].astype(float)) for _, _, group in groups))
    equal = min(steps) if steps else None
    engines = mine[mine["adapter"] != INHOUSE]
    groups += [(adapter, method, group)
               for (adapter, method), group in engines.groupby(["adapter", "method"], sort=True)]
    rows = tuple((who, method, *_sizes(group), *_cost_and_reach(group), *_at(group, equal))
                 for who, method, group in groups)
    at = "—" if equal is None else f"{equal:g} s"
    return Table(
        key=f"coordinates-{slug(scenario)}",
        caption=f"{scenario}: the in-house formulation in absolute and joint coordinates, "
                f"engines beside them",
        columns=("model", "method", "coordinates", "constraint equations",
                 "median wall time per step (µs)", "largest ok step (s)", f"status at {at}",
                 f"error at {at}"),
        rows=rows,
        note="One row per in-house method run in both coordinates and per model, then every "
             "engine method of the run. Cost: the median wall time per step of the row's ok "
             "cases. Equal step: the smallest step every in-house row ran (— when they share "
             "none). Largest ok step: of the steps this run tried (the stability sweep bisects "
             "it where the campaign has one).")


def _sizes(group: pd.DataFrame) -> tuple:
    sized = group.dropna(subset=["n_coordinates"])
    if sized.empty:
        return None, None
    first = sized.iloc[0]
    equations = first["n_constraint_equations"]
    return int(first["n_coordinates"]), None if pd.isna(equations) else int(equations)


def _cost_and_reach(group: pd.DataFrame) -> tuple:
    ok = group[group["status"] == CaseStatus.OK]
    if ok.empty:
        return None, None
    per_step = ok["wall_time_per_step_s"].astype(float).median()
    return (None if pd.isna(per_step) else float(per_step) * 1e6), float(ok["dt"].max())


def _at(group: pd.DataFrame, step: float | None) -> tuple:
    if step is None:
        return None, None
    there = group[group["dt"].astype(float) == step]
    if there.empty:
        return "not run", None
    case = there.iloc[0]
    error = case["main_output_error"] if case["status"] == CaseStatus.OK else None
    return _plain(case["status"]), _plain(error)
