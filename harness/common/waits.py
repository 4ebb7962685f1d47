"""Every wait of more than a moment says what it is: one line on stderr before it starts (what,
why, about how long) and one when it ends, through :mod:`logging` (logger ``mbh``, level INFO).

The command line shows them on stderr unless ``--quiet`` (:func:`show_on_stderr`); a program
using the API sees them once it configures logging, e.g. ``logging.basicConfig(level="INFO")``.
Nothing is written to stdout, so machine-readable output stays clean.
"""

from __future__ import annotations

import logging
import os
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager

LOG = logging.getLogger("mbh")

#: A wait shorter than this, s, gets no closing line.
QUIET_BELOW_S = 2.0


def show_on_stderr(quiet: bool = False) -> None:
    """Send the ``mbh`` logger's INFO lines to stderr as ``mbh: …`` (the command line's setting);
    with ``quiet`` only warnings and errors.

    The handler writes to a duplicate of descriptor 2 taken now, so that a line said while an
    engine's output is captured (:func:`mbh._harness.common.capture.captured_output`, which points
    descriptor 2 at a file) still reaches the terminal rather than the case's notes.  A second
    call replaces the first one's handler.
    """
    for handler in [h for h in LOG.handlers if getattr(h, "_mbh_stderr", False)]:
        LOG.removeHandler(handler)
        handler.close()
        if handler._mbh_owned:  # the duplicate made below; never a stream someone else owns
            handler.stream.close()
    try:
        stream = os.fdopen(os.dup(sys.stderr.fileno()), "w", buffering=1,
                           encoding=sys.stderr.encoding or "utf-8", errors="backslashreplace")
        owned = True
    except (AttributeError, OSError, ValueError):  # a stderr without a descriptor (a capture)
        stream, owned = sys.stderr, False
    handler = logging.StreamHandler(stream)
    handler.setFormatter(logging.Formatter("mbh: %(message)s"))
    handler._mbh_stderr, handler._mbh_owned = True, owned
    LOG.addHandler(handler)
    LOG.propagate = False
    LOG.setLevel(logging.WARNING if quiet else logging.INFO)


def shown_on_stderr() -> bool:
    """Whether this process says its waits on stderr (:func:`show_on_stderr`, not quiet)."""
    return LOG.isEnabledFor(logging.INFO) and any(getattr(handler, "_mbh_stderr", False)
                                                  for handler in LOG.handlers)


def duration(seconds: float) -> str:
    """``seconds`` as a person reads a wait: ``40 s``, ``3 min``."""
    if seconds < 90:
        return f"{seconds:.0f} s"
    return f"{seconds / 60:.0f} min"


@contextmanager
def said(what: str, why: str = "", estimate_s: float | None = None) -> Iterator[None]:
    """Announce the wait ``what`` (with ``why`` and ``~estimate_s``) before the block and its
    measured length after it, when that took :data:`QUIET_BELOW_S` or more."""
    detail = ", ".join(part for part in (why, estimate_s and f"~{duration(estimate_s)}") if part)
    LOG.info("%s%s …", what, f" ({detail})" if detail else "")
    began = time.monotonic()
    try:
        yield
    finally:
        took = time.monotonic() - began
        if took >= QUIET_BELOW_S:
            LOG.info("%s: done in %s", what, duration(took))
