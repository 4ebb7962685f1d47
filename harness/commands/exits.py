"""What an ``mbh`` exit status says (docs/commands.md, "Exit status").

* :data:`OK` — the command did what was asked, and what it judged passed;
* :data:`NOT_PASSED` — what it judged did not pass: a case that is not ``ok`` or not accurate, a
  mechanism the assembly refuses, an adapter that cannot be used, a refused reference, a nightly
  regression, an engine that cannot represent the mechanism;
* :data:`BAD_INPUT` — bad input or usage, before anything was judged (argparse's own status);
* :data:`REPORT_FAILED` — ``mbh nightly``: no regression, but a report could not be built;
* 128 + N — stopped by signal N (:func:`interrupted`).
"""

from __future__ import annotations

import signal

from mbh._adapters.base import UnsupportedCase
from mbh._harness.common.errors import MbhError
from mbh._harness.jobs.nightly import REPORT_FAILED

__all__ = ["OK", "NOT_PASSED", "BAD_INPUT", "REPORT_FAILED", "SUMMARY", "UsageError",
           "interrupted", "status_of"]

OK = 0
NOT_PASSED = 1
BAD_INPUT = 2

#: The statuses in a line, for ``mbh --help``.
SUMMARY = ("exit status: 0 ok; 1 not passed (a case not ok or not accurate, a mechanism or "
           "adapter refused, a regression); 2 bad input or usage; 3 (nightly) a report not "
           "built; 128+N stopped by signal N. See docs/commands.md.")


class UsageError(MbhError, ValueError):
    """A problem with the command line the project's own errors do not name (a run that does
    not exist, a ``--where`` expression pandas refuses); printed without a traceback."""


def status_of(error: MbhError | UnsupportedCase) -> int:
    """The exit status of an error that stopped a command.

    A refused computation (the project's errors on ``RuntimeError``: a reference whose routes
    disagree) and a mechanism the engine cannot represent are results that did not pass; every
    other project error is bad input (``ValueError`` based: a file with mistakes, an unknown
    name, a step that does not fit).
    """
    return NOT_PASSED if isinstance(error, (RuntimeError, UnsupportedCase)) else BAD_INPUT


def interrupted(stop: KeyboardInterrupt) -> int:
    """The shell's exit status of a command stopped by a signal: 128 + its number (130 for
    Ctrl-C, 143 for SIGTERM, 129 for SIGHUP)."""
    return 128 + int(getattr(stop, "signum", signal.SIGINT))
