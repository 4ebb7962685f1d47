"""The result store's schema: column types, the version, and the migrations from older versions.

A run folder holds ``manifest.json`` and the case rows as Parquet part files (see
:mod:`mbh._harness.store.runs`).  Each part file records the schema version it was written with in its
Parquet key-value metadata (:data:`VERSION_KEY`); a part without it takes the manifest's version.
Reading applies :func:`migrate_table` and :func:`migrate_manifest`, so every reader sees the
current layout, whatever version wrote the files.

Versions
--------
1
    The store's first layout (the prototype of issue 10, before the campaign rows were fixed):
    the per-case wall time was the column ``wall_time`` (s, median over repetitions), there was
    no per-step time column and no per-simulated-second column, and the manifest had no
    machine-speed ``calibration_s`` (runs could not be compared by calibrated time).
2
    ``wall_time`` renamed ``wall_time_s``; ``wall_time_per_sim_s`` (= wall_time_s / t_end) and
    ``wall_time_per_step_s`` (= wall_time_s / steps, NaN when no step was taken) added; the
    manifest gains ``calibration_s`` (None until the calibration case ran).
"""

from __future__ import annotations

import pyarrow as pa
import pyarrow.compute as pc

from mbh._harness.common.errors import MbhError

#: The layout this code writes.
SCHEMA_VERSION = 2

#: Parquet key-value metadata key holding a part file's schema version.
VERSION_KEY = b"mbh_schema_version"

_STRING = pa.string()
_FLOAT = pa.float64()
_INT = pa.int64()
_BOOL = pa.bool_()

#: Declared types of the case-row columns (the row of ``mbh._harness.run.row``, plus ``run_id`` and
#: ``trajectory_file`` added by the store).  Declared columns always get this type, so parts
#: written with a None in one column and a float in the next concatenate; columns not declared
#: here (``error_<output>``, further metrics) are typed from their Python value.
CASE_COLUMNS: dict[str, pa.DataType] = {
    "run_id": _STRING,
    "case_id": _STRING,
    "scenario": _STRING,
    "scenario_hash": _STRING,
    "adapter": _STRING,
    "adapter_version": _STRING,
    "method": _STRING,
    "dt": _FLOAT,
    "t_end": _FLOAT,
    "repetitions": _INT,
    "status": _STRING,
    "reason": _STRING,
    "failure_time": _FLOAT,
    "accurate": _BOOL,
    "main_output": _STRING,
    "main_output_error": _FLOAT,
    "wall_time_s": _FLOAT,
    "wall_time_per_sim_s": _FLOAT,
    "wall_time_per_step_s": _FLOAT,
    "wall_times_s": _STRING,
    "steps": _INT,
    "rhs_evals": _INT,
    "counters": _STRING,
    "notes": _STRING,
    "n_coordinates": _INT,
    "n_constraint_equations": _INT,
    "n_redundant_equations": _INT,
    "model_notes": _STRING,
    "max_constraint_violation": _FLOAT,
    "max_velocity_violation": _FLOAT,
    "max_energy_error_J": _FLOAT,
    "max_energy_error_rel": _FLOAT,
    "reference": _STRING,
    "packages": _STRING,
    "trajectory_file": _STRING,
    "reused_from": _STRING,
}

#: Declared types of the stability-sweep columns known to the store (others are inferred).
SWEEP_COLUMNS: dict[str, pa.DataType] = {
    "run_id": _STRING,
    "sweep_id": _STRING,
    "scenario": _STRING,
    "adapter": _STRING,
    "method": _STRING,
}


def _migrate_table_1_to_2(table: pa.Table) -> pa.Table:
    """Rename ``wall_time`` and add the per-simulated-second and per-step times."""
    if "wall_time" in table.column_names:
        table = table.rename_columns(
            ["wall_time_s" if name == "wall_time" else name for name in table.column_names])
    wall = table.column("wall_time_s").cast(_FLOAT)
    if "wall_time_per_sim_s" not in table.column_names:
        table = table.append_column("wall_time_per_sim_s",
                                    pc.divide(wall, table.column("t_end").cast(_FLOAT)))
    if "wall_time_per_step_s" not in table.column_names:
        steps = table.column("steps").cast(_FLOAT)
        stepped = pc.greater(steps, 0.0)
        per_step = pc.if_else(stepped, pc.divide(wall, steps), float("nan"))
        table = table.append_column("wall_time_per_step_s", per_step)
    return table


def _migrate_manifest_1_to_2(manifest: dict) -> dict:
    """Add the (unknown) calibration figure."""
    return {**manifest, "calibration_s": manifest.get("calibration_s")}


_TABLE_MIGRATIONS = {1: _migrate_table_1_to_2}
_MANIFEST_MIGRATIONS = {1: _migrate_manifest_1_to_2}


class SchemaError(MbhError, ValueError):
    """A stored file has a schema version this code cannot read (names file and version)."""


def _check_version(version: int, source: str) -> None:
    if not isinstance(version, int) or not 1 <= version <= SCHEMA_VERSION:
        raise SchemaError(f"{source}: schema version {version!r} is not one this code reads "
                          f"(1..{SCHEMA_VERSION}); a newer mbh wrote it?")


def migrate_table(table: pa.Table, version: int, source: str) -> pa.Table:
    """``table`` of case rows written at schema ``version``, brought to :data:`SCHEMA_VERSION`.

    Raises
    ------
    SchemaError
        For a version outside 1..SCHEMA_VERSION (``source`` names the file).
    """
    _check_version(version, source)
    for step in range(version, SCHEMA_VERSION):
        table = _TABLE_MIGRATIONS[step](table)
    return table


def migrate_manifest(manifest: dict, source: str) -> dict:
    """``manifest`` brought to :data:`SCHEMA_VERSION` (its ``schema_version`` says where from).

    The returned manifest records the version the run was created with as
    ``created_schema_version`` (kept through later rewrites): part files without a version in
    their metadata were written at that version.
    """
    version = manifest.get("schema_version")
    _check_version(version, source)
    for step in range(version, SCHEMA_VERSION):
        manifest = _MANIFEST_MIGRATIONS[step](manifest)
    created = manifest.get("created_schema_version", version)
    return {**manifest, "schema_version": SCHEMA_VERSION, "created_schema_version": created}


def column_type(columns: dict[str, pa.DataType], name: str, value) -> pa.DataType:
    """The Parquet type of column ``name`` holding ``value`` (declared, else from the value).

    Raises
    ------
    TypeError
        When ``value`` is not a scalar (str, float, int, bool or None).
    """
    if name in columns:
        return columns[name]
    if value is None:
        return pa.null()
    for python_type, arrow_type in ((bool, _BOOL), (int, _INT), (float, _FLOAT), (str, _STRING)):
        if isinstance(value, python_type):
            return arrow_type
    raise TypeError(f"row column {name!r}: a {type(value).__name__} is not a scalar "
                    f"(str, float, int, bool or None): {value!r}")
