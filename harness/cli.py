"""The ``mbh`` command line.

The commands live in :mod:`mbh._harness.commands`, one module per group; this module builds the
parser from them and runs the one asked for.  Whatever stops a command is turned into one message
on stderr and an exit status here (:mod:`mbh._harness.commands.exits`; docs/commands.md, "Exit
status"): a user error (bad scenario file, unknown method, a step that does not fit the sample
grid, a mechanism that cannot be assembled) is one clear message per problem and status 2, never
a traceback.

``--json`` output is strict JSON (RFC 8259), whatever the numbers: a non-finite value is written
as one of the strings ``"NaN"``, ``"Infinity"``, ``"-Infinity"``
(:mod:`mbh._harness.common.jsonout`), and what an engine library prints while a case runs is
captured at the file-descriptor level and kept in the case's ``notes``, never on stdout
(:mod:`mbh._harness.common.capture`).
"""

from __future__ import annotations

import argparse
import importlib.metadata
import sys

from mbh._adapters.base import UnsupportedCase
from mbh._harness.commands import (campaigns, catalog, exits, reports, results, scenes,
                                   simulate, speed)
from mbh._harness.common import capture, waits
from mbh._harness.common.errors import MbhError

#: The command groups, in the order ``mbh --help`` lists their commands.
COMMAND_GROUPS = (catalog, scenes, simulate, speed, campaigns, results, reports)


def version() -> str:
    """The installed distribution's version (``unknown`` when mbh runs uninstalled)."""
    try:
        return importlib.metadata.version("mbh")
    except importlib.metadata.PackageNotFoundError:
        return "unknown"


def build_parser() -> argparse.ArgumentParser:
    """The parser of every command, each parser's ``func`` the function that runs it."""
    parser = argparse.ArgumentParser(prog="mbh", description=__doc__.splitlines()[0],
                                     epilog=exits.SUMMARY)
    parser.add_argument("--version", action="version", version=f"%(prog)s {version()}")
    sub = parser.add_subparsers(dest="command", required=True)
    for group in COMMAND_GROUPS:
        group.add_commands(sub)
    return parser


def main(argv=None) -> int:
    """Run ``mbh ARGV`` and return its exit status (docs/commands.md, "Exit status")."""
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as stop:  # --help, --version, or a usage error argparse has printed
        return stop.code
    waits.show_on_stderr(quiet=getattr(args, "quiet", False))
    try:
        with capture.answers_only_on_stdout():
            return args.func(args)
    except (MbhError, UnsupportedCase) as error:
        print(f"mbh: {error}", file=sys.stderr)
        return exits.status_of(error)
    except KeyboardInterrupt as stop:
        print("mbh: interrupted", file=sys.stderr)
        return exits.interrupted(stop)
    except BrokenPipeError:  # output piped into a pager or head that closed early
        sys.stderr.close()
        return exits.OK


if __name__ == "__main__":
    raise SystemExit(main())
