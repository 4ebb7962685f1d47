"""Every file the store writes, written whole or not at all: to a dot-prefixed temporary name
beside it, synced, then renamed into place (``os.replace``), so a reader never meets half a file
and a killed writer leaves only a temporary file that no reader opens.
"""

from __future__ import annotations

import os
import threading
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from mbh._harness.common import jsonout

__all__ = ["write_bytes", "write_json", "write_table", "write_arrays"]


def _atomic_write(path: Path, write) -> None:
    """Call ``write(file)`` on a dot-prefixed temp file beside ``path``, then rename it."""
    temp = path.with_name(f".{path.name}.tmp-{os.getpid()}-{threading.get_ident()}")
    try:
        with open(temp, "wb") as file:
            write(file)
            file.flush()
            os.fsync(file.fileno())
        os.replace(temp, path)
    finally:
        temp.unlink(missing_ok=True)


def write_bytes(path: Path, data: bytes) -> None:
    """``data`` as the file ``path``."""
    _atomic_write(path, lambda file: file.write(data))


def write_json(path: Path, document: dict) -> None:
    """``document`` as JSON (:mod:`mbh._harness.common.jsonout`) in ``path``."""
    _atomic_write(path, lambda file: file.write(jsonout.dumps(document).encode()))


def write_table(path: Path, table: pa.Table) -> None:
    """``table`` as the Parquet file ``path``."""
    _atomic_write(path, lambda file: pq.write_table(table, file))


def write_arrays(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """``arrays`` as the npz file ``path`` (one entry per key)."""
    _atomic_write(path, lambda file: np.savez(file, **arrays))
