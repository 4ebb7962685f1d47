"""Case and sweep rows as Parquet: one row as a typed one-row table, the tables read back migrated
to the current schema, and :class:`PartTable`, a table kept as numbered part files (one per
append) that reading concatenates in write order, keeping the first row of each key and leaving
out (and reporting) damaged parts.

Column types are declared in :mod:`mbh._harness.store.schema`.
"""

from __future__ import annotations

import re
import threading
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from mbh._harness.store.files import write_table
from mbh._harness.store.problems import DAMAGE
from mbh._harness.store.schema import (CASE_COLUMNS, SCHEMA_VERSION, VERSION_KEY, SchemaError,
                                       column_type, migrate_table)

__all__ = ["row_table", "read_table", "case_frame", "PartTable"]

_PART = re.compile(r"^part-(\d+)\.parquet$")
# Nullable pandas dtypes for integer and boolean columns, so a None keeps them integer/boolean.
_PANDAS_TYPES = {pa.int64(): pd.Int64Dtype(), pa.bool_(): pd.BooleanDtype()}.get


def _scalar(value):
    return value.item() if isinstance(value, np.generic) else value


def row_table(row: dict, columns: dict[str, pa.DataType]) -> pa.Table:
    """One-row table of ``row`` with declared column types, tagged with the schema version.

    Raises
    ------
    TypeError
        Naming the column whose value is not a scalar or does not fit its declared type.
    """
    arrays, fields = [], []
    for name, value in row.items():
        value = _scalar(value)
        kind = column_type(columns, name, value)
        try:
            arrays.append(pa.array([value], type=kind))
        except (pa.ArrowInvalid, pa.ArrowTypeError, TypeError) as error:
            raise TypeError(f"row column {name!r}: {value!r} is not a {kind}: {error}") from None
        fields.append(pa.field(name, kind))
    schema = pa.schema(fields, metadata={VERSION_KEY: str(SCHEMA_VERSION).encode()})
    return pa.Table.from_arrays(arrays, schema=schema)


def read_table(path: Path, fallback_version: int) -> pa.Table:
    """The table in ``path`` migrated to the current schema."""
    table = pq.read_table(path)
    metadata = table.schema.metadata or {}
    version = int(metadata[VERSION_KEY]) if VERSION_KEY in metadata else fallback_version
    return migrate_table(table.replace_schema_metadata(None), version, str(path))


def _to_frame(table: pa.Table | None, columns: dict[str, pa.DataType]) -> pd.DataFrame:
    """``table`` (None: no rows, the declared ``columns``) as a DataFrame with nullable integer
    and boolean columns."""
    if table is None:
        table = pa.schema(list(columns.items())).empty_table()
    return table.to_pandas(types_mapper=_PANDAS_TYPES)


def case_frame(row: dict) -> pd.DataFrame:
    """One case row as a one-row DataFrame with the column types
    :func:`mbh._harness.store.runs.load_run` gives.

    Raises
    ------
    TypeError
        Naming the column whose value does not fit its declared type.
    """
    return _to_frame(row_table(row, CASE_COLUMNS), CASE_COLUMNS)


class PartTable:
    """A table kept as numbered Parquet part files in one folder (one file per append).

    Parameters
    ----------
    folder : Path
        Where the parts live.
    columns : dict
        Declared column types (:mod:`mbh._harness.store.schema`).
    key : str
        Column identifying a row; reading keeps the first row of each key (when present).
    fallback_version : int
        Schema version of parts whose metadata does not say.
    on_problem : callable
        ``on_problem(path, problem)``, called for each damaged part (which reading skips).
    """

    def __init__(self, folder: Path, columns: dict[str, pa.DataType], key: str,
                 fallback_version: int, on_problem):
        self.folder, self.columns, self.key = folder, columns, key
        self.fallback_version = fallback_version
        self.on_problem = on_problem
        self._lock = threading.Lock()
        self._types: dict[str, pa.DataType] | None = None  # undeclared columns seen so far

    def _check_types(self, table: pa.Table) -> None:
        """Refuse an undeclared column whose type differs from the one earlier parts hold.

        Integer and float mix (read as float), None fits any type; anything else would make
        the parts impossible to concatenate, so it is refused here, at write time.

        Raises
        ------
        TypeError
            Naming the column, its new type and the type already stored.
        """
        if self._types is None:
            self._types = {}
            for path in self.parts():
                schema = self._readable(path, pq.read_schema)
                if schema is not None:
                    self._record(schema)
        for field in table.schema:
            known = self._types.get(field.name)
            if field.name in self.columns or pa.types.is_null(field.type) or known is None:
                continue
            numeric = {known, field.type} <= {pa.int64(), pa.float64()}
            if known != field.type and not numeric:
                raise TypeError(f"row column {field.name!r}: a {field.type} value, but earlier "
                                f"rows of this run hold {known} there")
        self._record(table.schema)

    def _record(self, schema: pa.Schema) -> None:
        for field in schema:
            if field.name in self.columns or pa.types.is_null(field.type):
                continue
            if self._types.get(field.name) != pa.float64():
                self._types[field.name] = field.type

    def parts(self) -> list[Path]:
        """Finished part files in write order (temp files excluded)."""
        if not self.folder.is_dir():
            return []
        numbered = [(int(m.group(1)), p) for p in self.folder.iterdir()
                    if (m := _PART.match(p.name))]
        return [path for _, path in sorted(numbered)]

    def append(self, row: dict) -> None:
        """Write ``row`` (a flat dict of scalars) as the next part file.

        Raises
        ------
        TypeError
            When a value does not fit its column's declared type, or an undeclared column's
            type differs from the one earlier parts hold there.
        """
        table = row_table(row, self.columns)
        with self._lock:
            self._check_types(table)
            self.folder.mkdir(parents=True, exist_ok=True)
            parts = self.parts()
            number = int(_PART.match(parts[-1].name).group(1)) + 1 if parts else 0
            write_table(self.folder / f"part-{number:06d}.parquet", table)

    def _readable(self, path: Path, read):
        """``read(path)``, or None for a damaged part (reported, with its rows left out)."""
        try:
            return read(path)
        except SchemaError:  # a newer mbh wrote it: not damage, and not to be skipped
            raise
        except DAMAGE as error:
            self.on_problem(path, f"damaged part file ({type(error).__name__}: {error}); its "
                                  f"rows are left out")
            return None

    def damaged(self) -> list[Path]:
        """Part files that cannot be read as tables."""
        return [path for path in self.parts()
                if self._readable(path, lambda p: read_table(p, self.fallback_version)) is None]

    def keys(self) -> set[str]:
        """The key of every row in a readable part (damaged parts reported)."""
        keys = set()
        for path in self.parts():
            column = self._readable(path, lambda p: pq.read_table(p, columns=[self.key])
                                    if self.key in pq.read_schema(p).names else None)
            if column is not None:
                keys.update(column.column(0).to_pylist())
        return keys

    def _concatenated(self, tables: list[tuple[Path, pa.Table]]) -> pa.Table:
        """The tables as one; a part whose columns fit none of the others' types is reported
        and left out."""
        try:
            return pa.concat_tables([t for _, t in tables], promote_options="permissive")
        except (pa.ArrowInvalid, pa.ArrowTypeError):
            pass
        table = tables[0][1]
        for path, part in tables[1:]:
            try:
                table = pa.concat_tables([table, part], promote_options="permissive")
            except (pa.ArrowInvalid, pa.ArrowTypeError) as error:
                self.on_problem(path, f"damaged part file (its columns do not fit the other "
                                      f"parts': {error}); its rows are left out")
        return table

    def table(self) -> pa.Table | None:
        """All rows, migrated, first row per key; None when there is no readable part."""
        tables = [(path, table) for path in self.parts()
                  if (table := self._readable(path, lambda p: read_table(
                      p, self.fallback_version))) is not None]
        if not tables:
            return None
        table = self._concatenated(tables)
        if self.key not in table.column_names:
            return table
        keys = table.column(self.key).to_pylist()
        seen, first = set(), []
        for index, key in enumerate(keys):
            if key not in seen:
                seen.add(key)
                first.append(index)
        return table.take(first)

    def frame(self) -> pd.DataFrame:
        """:meth:`table` as a DataFrame (no rows: the declared columns)."""
        return _to_frame(self.table(), self.columns)
