"""The project's error base class.

Every error a user can meet from bad input or a refused result derives from :class:`MbhError`, so
a caller catches the project's errors in one ``except MbhError`` clause.  Each subclass also keeps
the built-in base it had (``ValueError`` for bad input, ``RuntimeError`` for a refused
computation), so existing ``except ValueError`` clauses go on working.
"""

from __future__ import annotations

__all__ = ["MbhError"]


class MbhError(Exception):
    """Base class of every user-facing error of ``mbh``: the message names the file, the field
    or the case and the problem."""
