"""Progress bars: the campaign's (cases done out of the total, ETA, and the failures so far) and
a reference build's (stages of estimated cost, with the time left).

Drawn on stderr with tqdm, and only when stderr is a terminal and the caller did not ask for quiet,
so a log file or a pipe never receives bar frames.
"""

from __future__ import annotations

import sys
import threading
import time
from collections import Counter

from tqdm import tqdm

from mbh._harness.common.status import CaseStatus


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
        if status != CaseStatus.OK:
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


class StageProgress:
    """A bar over stages of estimated cost, in seconds, with the time left: inside a stage it
    advances with the clock but never past the stage's estimate; when the stage ends it jumps to
    the stage's end (the estimate was long) or waits there (short).

    Parameters
    ----------
    description : str
        Shown left of the bar.
    estimates : list of float
        Estimated wall time of each stage, s.
    enabled : bool
        Draw the bar (see :func:`progress_wanted`); when False every call is a no-op.
    """

    #: Seconds between two clock updates of the bar.
    TICK = 0.5

    def __init__(self, description: str, estimates: list[float], enabled: bool):
        self._estimates = [max(float(e), 0.0) for e in estimates]
        self._bar = tqdm(total=sum(self._estimates), unit="s", desc=description,
                         file=sys.stderr, disable=not enabled, dynamic_ncols=True,
                         bar_format="{desc}: {percentage:3.0f}%|{bar}| "
                                    "[{elapsed} elapsed, ~{remaining} left]{postfix}")
        self._enabled = enabled
        self._done = 0.0

    def run(self, index: int, name: str, work):
        """``work()`` as stage ``index`` (its name shown beside the bar); returns its result."""
        if not self._enabled:
            return work()
        self._bar.set_postfix_str(name, refresh=True)
        stop = threading.Event()
        start, end = self._done, self._done + self._estimates[index]

        def tick():
            began = time.monotonic()
            while not stop.wait(self.TICK):
                self._move_to(min(start + time.monotonic() - began, end))

        ticker = threading.Thread(target=tick, daemon=True)
        ticker.start()
        try:
            return work()
        finally:
            stop.set()
            ticker.join()
            self._move_to(end)

    def _move_to(self, position: float) -> None:
        if position > self._done:
            self._bar.update(position - self._done)
            self._done = position

    def close(self) -> None:
        self._bar.close()

    def __enter__(self) -> "StageProgress":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
