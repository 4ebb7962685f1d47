"""The campaign's progress bar: cases done out of the total, ETA, and the failures so far.

Drawn on stderr with tqdm, and only when stderr is a terminal and the caller did not ask for quiet,
so a log file or a pipe never receives bar frames.
"""

from __future__ import annotations

import sys
from collections import Counter

from tqdm import tqdm


def progress_wanted(requested: bool) -> bool:
    """Whether to draw the bar: asked for, and stderr is a terminal."""
    return requested and sys.stderr.isatty()


class CaseProgress:
    """A bar over ``total`` cases whose postfix counts the rows that did not end ``ok``.

    Parameters
    ----------
    total : int
        Number of cases the bar runs to.
    enabled : bool
        Draw the bar (see :func:`progress_wanted`); when False every call is a no-op.
    """

    def __init__(self, total: int, enabled: bool):
        self._bar = tqdm(total=total, unit="case", file=sys.stderr, disable=not enabled,
                         dynamic_ncols=True)
        self._failures = Counter()

    def update(self, row: dict) -> None:
        """Count one finished case (its row's ``status``)."""
        status = row.get("status", "")
        if status != "ok":
            self._failures[status] += 1
            self._bar.set_postfix_str(
                "failures " + ", ".join(f"{k}={v}" for k, v in sorted(self._failures.items())),
                refresh=False)
        self._bar.update(1)

    def close(self) -> None:
        self._bar.close()

    def __enter__(self) -> "CaseProgress":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
