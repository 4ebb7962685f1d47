"""The options several ``mbh`` commands share, declared once, and the argument types that check
a value as argparse reads it (a bad value: argparse's usage message and exit status 2).

A command attaches what it takes with :func:`shared`, e.g. ``shared(parser, "root", "json")``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from mbh._harness.measure.verdict import Bounds

__all__ = ["shared", "positive_int", "positive_number", "above_one", "bounds", "SHARED"]

JSON_HELP = ('strict JSON on stdout; non-finite numbers as the strings "NaN", "Infinity", '
             '"-Infinity"')
QUIET_HELP = "no progress lines on stderr (what is being compiled or built, and how long)"
ROOT_HELP = ("results root (default: $MBH_RESULTS_DIR, else results/ in a checkout, else the "
             "user data folder)")
WORKERS_HELP = "local worker processes (default and maximum: the cores)"
BOUNDS_HELP = ("the verdict's bounds as NAME=VALUE,...: gap (joint gap / mechanism size, default "
               "%(gap)g), orientation (rad, %(orientation)g), energy (energy error / energy "
               "scale, %(energy)g), branch (distance from the reference's branch / mechanism "
               "size, %(branch)g), trajectory (distance from the reference at the same time / "
               "mechanism size, and a body's turn from it in rad, %(trajectory)g); see "
               "harness/measure/verdict.py" % vars(Bounds()))


def positive_int(text: str) -> int:
    """A whole number of at least 1."""
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number of at least 1, got {text!r}")
    return value


def positive_number(text: str) -> float:
    """A finite number above 0."""
    return _number_above(text, 0.0)


def above_one(text: str) -> float:
    """A finite number above 1 (a factor a quantity must grow by)."""
    return _number_above(text, 1.0)


def _number_above(text: str, least: float) -> float:
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not least < value < float("inf"):
        raise argparse.ArgumentTypeError(f"expected a finite number above {least:g}, got {text!r}")
    return value


def bounds(text: str) -> Bounds:
    """The verdict's bounds from ``NAME=VALUE,...`` (:meth:`Bounds.parse`)."""
    try:
        return Bounds.parse(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


#: Shared option name → (flags, add_argument keywords).
SHARED = {
    "json": (("--json",), {"action": "store_true", "help": JSON_HELP}),
    "quiet": (("--quiet",), {"action": "store_true", "help": QUIET_HELP}),
    "root": (("--root",), {"type": Path, "default": None, "help": ROOT_HELP}),
    "workers": (("--workers",), {"type": positive_int, "default": None, "help": WORKERS_HELP}),
    "bounds": (("--bounds",), {"type": bounds, "default": "", "help": BOUNDS_HELP}),
}


def shared(parser: argparse.ArgumentParser, *names: str, **helps: str) -> None:
    """Add the shared options ``names`` (keys of :data:`SHARED`) to ``parser``.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        A command's parser.
    *names : str
        The options it takes, in the order its help lists them.
    **helps : str
        Option name → the help text this command gives it instead of the shared one.
    """
    for name in names:
        flags, keywords = SHARED[name]
        parser.add_argument(*flags, **(keywords | ({"help": helps[name]} if name in helps
                                                   else {})))
