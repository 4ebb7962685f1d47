"""How the commands print: strict JSON (:mod:`mbh._harness.common.jsonout`), plain tables, and
warnings on stderr."""

from __future__ import annotations

import sys

from mbh._harness.common import jsonout

__all__ = ["print_json", "print_table", "print_fields", "records", "cell", "status_counts",
           "warn_problems"]


def print_json(value) -> None:
    """``value`` as strict JSON on stdout (non-finite numbers as strings)."""
    print(jsonout.dumps(value))


def print_table(rows: list[dict], columns: list[str]) -> None:
    """``rows`` as left-aligned columns under a header line (a missing value: blank)."""
    widths = {c: max([len(c), *(len(str(r.get(c, ""))) for r in rows)]) for c in columns}
    print("  ".join(c.ljust(widths[c]) for c in columns))
    for row in rows:
        print("  ".join(str(row.get(c, "")).ljust(widths[c]) for c in columns))


def print_fields(fields: dict, width: int) -> None:
    """One ``key value`` line per item, the keys padded to ``width``."""
    for key, value in fields.items():
        print(f"{key:{width}s} {value}")


def records(frame) -> list[dict]:
    """Rows of ``frame`` as dicts of plain values (a missing value of a nullable column: None)."""
    import pandas as pd

    return [{key: None if value is pd.NA else value for key, value in row.items()}
            for row in frame.to_dict("records")]


def cell(value) -> str:
    """A table cell: a float to 3 significant digits, anything else as text."""
    return f"{value:.3g}" if isinstance(value, float) else str(value)


def status_counts(frame) -> str:
    """``"failed 2, ok 7"``: the cases of ``frame`` per status."""
    counts = frame["status"].value_counts() if len(frame) else {}
    return ", ".join(f"{status} {count}" for status, count in sorted(dict(counts).items()))


def warn_problems(problems) -> None:
    """Each damaged stored file on stderr (docs/formats/store.md, "Damaged files")."""
    for problem in problems:
        print(f"mbh: warning: {problem}", file=sys.stderr)
