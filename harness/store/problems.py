"""What goes wrong with stored files: the store's errors and warnings, what a damaged file is
named by, and the wrapper that turns a failed write into a :class:`StoreError` naming the file.

docs/formats/store.md, "Damaged files" and "A results root that is read-only or full".
"""

from __future__ import annotations

import contextlib
import errno
import zipfile
from dataclasses import dataclass
from pathlib import Path

from mbh._harness.common.errors import MbhError

__all__ = ["StoreError", "MissingTrajectory", "StoreWarning", "StoreProblem", "DAMAGE",
           "write_problem", "writing"]


class StoreError(MbhError, ValueError):
    """A results root, run folder or stored file that cannot be read or written as asked; the
    message names the file and the problem."""


class MissingTrajectory(MbhError, KeyError):
    """A case without a readable stored trajectory (none stored, or its file is damaged)."""

    def __str__(self) -> str:
        return str(self.args[0])


class StoreWarning(UserWarning):
    """Rows or files of a stored run left out because a file is damaged."""


@dataclass(frozen=True)
class StoreProblem:
    """A damaged file of a run and what reading left out because of it."""

    file: str
    problem: str

    def __str__(self) -> str:
        return f"{self.file}: {self.problem}"


#: What reading a damaged file raises: pyarrow's ArrowInvalid (a ValueError) for a cut or
#: overwritten Parquet file, BadZipFile or ValueError for an npz, JSONDecodeError, KeyError for a
#: missing column or array, TypeError for fields of the wrong kind, OSError for an unreadable file.
DAMAGE = (OSError, ValueError, KeyError, TypeError, EOFError, zipfile.BadZipFile)


def write_problem(path: Path, error: OSError) -> str:
    """``PATH: cannot write: REASON (what it means)`` for a failed write."""
    where = error.filename or path
    meaning = {errno.ENOSPC: "the disk is full", errno.EDQUOT: "the disk quota is used up",
               errno.EROFS: "the file system is read-only",
               errno.EACCES: "no permission to write there",
               errno.EPERM: "no permission to write there"}.get(error.errno)
    return f"{where}: cannot write: {error.strerror or error}" + (f" ({meaning})" if meaning
                                                                   else "")


@contextlib.contextmanager
def writing(path: Path):
    """Within the block, an OSError becomes a :class:`StoreError` naming the file."""
    try:
        yield
    except OSError as error:
        raise StoreError(write_problem(path, error)) from None
