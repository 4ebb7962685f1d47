"""The seed's published figures (Rouvinen 2003, ch. 7, tables 9–11) next to our re-run of its setup.

Published figures: ``harness/data/rouvinen2003_results.toml`` (transcribed with its citation).
Ours: the rows of ``mbh seed-table --json`` (:func:`mbh._harness.jobs.seedtable.seed_rows`), stored beside a
run as ``<run folder>/seed_table.json`` by ``make report``; the report never re-runs them.

Nothing here is tuned to match: a row shows theirs, ours and ours / theirs, and :data:`NOTES`
says how the two measure differently.
"""

from __future__ import annotations

import json
import statistics
import tomllib
from pathlib import Path

from mbh._harness.common.errors import MbhError
from mbh._harness.report.summary import Table

#: The published results, as shipped with the package.
PUBLISHED_PATH = Path(__file__).resolve().parent.parent / "data" / "rouvinen2003_results.toml"

#: Name of our seed-table file in a run folder.
SEED_TABLE_FILE = "seed_table.json"

#: Seed mechanism → our scenario (the four-bar is the seed's spatial model).
SCENARIOS = {"four_bar": "fourbar_spatial", "slider_crank": "slider_crank"}
#: Seed integrator → ours (Gear's 4th-order predictor-corrector ↔ our fixed-step BDF4).
INTEGRATORS = {"rk4": "rk4", "rkn4": "rkn4", "gear": "bdf4"}
STABILISATIONS = ("none", "baumgarte", "direct")

#: Published table → (our seed-table column, quantity, unit of ours).
QUANTITIES = {
    "table9_max_constraint_error": ("max_violation", "max constraint error", "m"),
    "table10_mean_constraint_error": ("mean_violation", "mean constraint error", "m"),
    "table11_max_energy_error_J": ("max_energy_error_J", "max energy-balance error", "J"),
}

#: How the two sides measure differently (shown with the table; Rouvinen 2003, ch. 7; seedtable.py).
NOTES = (
    "Constraint error: the seed takes the largest absolute entry of its constraint vector Φ, which "
    "mixes positions (m), direction-cosine products and the Euler-parameter normalisation "
    "(dimensionless); ours is the neutral joint gap in metres (or lever × orientation residual), "
    "the same measure for every engine. The two are not the same quantity, so ratios of order "
    "one, not equality, are what agreement can mean here.",
    "Energy balance: both are the largest |T + V − W| over the run, in J (ours from body states "
    "sampled every 0.01 s, harness/measure/energy.py, relative to the start). With the deliberately "
    "large step of the seed's setup this figure is dominated by the integration error, so it "
    "is sensitive to every detail of the two implementations.",
    "Integrators: the seed's Gear is a 4th-order predictor-corrector with iteration tolerance "
    "1e-5; ours is fixed-step BDF4 with an iteration tolerance of 1e-5 (same order and "
    "tolerance; the start-up and the corrector are our own). RK4 and RKN4 are the classical "
    "methods in both.",
    "Stabilisation: Baumgarte α = β = 5 and direct violation correction (position and velocity "
    "projection) in both; the seed publishes no Gear figures with direct correction in tables "
    "9–10.",
    "Times: the seed's computing times (2003 hardware, its own code) are not transcribed; ours are "
    "in the seed-table file but compare only with each other.",
)


class SeedTableError(MbhError, ValueError):
    """A seed-table file that cannot be read (names the file and the problem)."""


def load_published(path: Path = PUBLISHED_PATH) -> dict:
    """The published results file, parsed (TOML)."""
    with open(path, "rb") as handle:
        return tomllib.load(handle)


def _json_float(value):
    """A JSON value of ``mbh seed-table --json`` as a float (its "NaN"/"Infinity" strings too);
    None stays None."""
    if value is None:
        return None
    return float(value)


def load_ours(run_path: Path) -> list[dict] | None:
    """Our seed-table rows stored beside the run, or None when the run has none.

    Raises
    ------
    SeedTableError
        When the file exists but is not a list of seed-table rows.
    """
    path = Path(run_path) / SEED_TABLE_FILE
    if not path.is_file():
        return None
    try:
        rows = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as error:
        raise SeedTableError(f"{path}: not valid JSON: {error}") from None
    needed = {"scenario", "integrator", "stabilisation", "status"}
    if not isinstance(rows, list) or not all(isinstance(r, dict) and needed <= r.keys()
                                             for r in rows):
        raise SeedTableError(f"{path}: expected the list of rows of `mbh seed-table --json` "
                             f"(each with {', '.join(sorted(needed))})")
    return rows


def _ratio(ours, theirs):
    if ours is None or theirs is None or theirs == 0:
        return None
    return ours / theirs


def comparison_table(published: dict, ours: list[dict]) -> Table:
    """Theirs, ours and ours / theirs for every published entry of tables 9–11."""
    index = {(r["scenario"], r["integrator"], r["stabilisation"]): r for r in ours}
    rows = []
    for table, (column, quantity, unit) in QUANTITIES.items():
        for seed_name, scenario in SCENARIOS.items():
            for stabilisation in STABILISATIONS:
                entries = published[table][seed_name].get(stabilisation, {})
                for seed_integrator, integrator in INTEGRATORS.items():
                    if seed_integrator not in entries:
                        continue
                    theirs = float(entries[seed_integrator])
                    row = index.get((scenario, integrator, stabilisation))
                    mine = None if row is None else _json_float(row.get(column))
                    rows.append((f"{quantity} ({unit} ours)", scenario, seed_integrator,
                                 stabilisation, theirs, mine, _ratio(mine, theirs),
                                 "not in our table" if row is None else row["status"]))
    return Table(key="seed-compare", caption="Rouvinen 2003 tables 9–11 (theirs) next to our "
                 "re-run of the same setup (ours)",
                 columns=("quantity", "scenario", "integrator (seed)", "stabilisation", "theirs",
                          "ours", "ours / theirs", "our status"),
                 rows=tuple(rows))


def newton_table(published: dict, ours: list[dict]) -> Table:
    """Mean Newton (corrector) iterations per step of Gear/BDF4: published vs ours per
    stabilisation."""
    rows = []
    for seed_name, scenario in SCENARIOS.items():
        theirs = float(published["gear_mean_newton_iterations_per_step"][seed_name])
        mine = [row for row in ours
                if row["scenario"] == scenario and row["integrator"] == INTEGRATORS["gear"]]
        for row in mine:
            value = _json_float(row.get("newton_per_step"))
            rows.append((scenario, row["stabilisation"], theirs, value, _ratio(value, theirs)))
        if not mine:
            rows.append((scenario, None, theirs, None, None))
    return Table(key="seed-newton", caption="Gear (ours: BDF4) mean corrector iterations per step",
                 columns=("scenario", "stabilisation", "theirs", "ours", "ours / theirs"),
                 rows=tuple(rows),
                 note="The seed gives one figure per mechanism without naming the stabilisation.")


def ratio_summary(table: Table) -> list[str]:
    """Per quantity: how many entries differ from the published ones by more than 10× either
    way, and the median ratio (sentences for the report)."""
    lines = []
    for quantity in dict.fromkeys(row[0] for row in table.rows):
        ratios = [row[6] for row in table.rows if row[0] == quantity and row[6] is not None]
        if not ratios:
            lines.append(f"{quantity}: no entry of ours to compare.")
            continue
        far = sum(1 for r in ratios if not 0.1 <= r <= 10.0)
        lines.append(f"{quantity}: {len(ratios)} entries, median ours / theirs "
                     f"{statistics.median(ratios):.3g}; {far} differ by more than 10× either way.")
    return lines
