"""Capture what engine libraries print, at the file-descriptor level.

C libraries (SUNDIALS, Bullet, MuJoCo) write with ``printf``/``fprintf`` straight to file
descriptors 1 and 2, past Python's ``sys.stdout``, so ``contextlib.redirect_stdout`` does not
catch them.  :func:`captured_output` points both descriptors at a temporary file for the duration
of a block (``os.dup``/``os.dup2``), flushing Python's and C's stdio buffers on the way in and out
so that nothing printed inside lands outside, and hands back the text.  The redirection is
process-wide: do not run two captured blocks in threads of one process at once.
:func:`answers_only_on_stdout` keeps a command's answer alone on stdout: what C code writes to
descriptor 1 meanwhile goes to stderr.
"""

from __future__ import annotations

import ctypes
import os
import sys
import tempfile
from contextlib import contextmanager
from dataclasses import dataclass

#: Longest engine message kept in a case's notes, characters.
NOTE_LIMIT = 2000
_DESCRIPTORS = (1, 2)


@dataclass
class Captured:
    """What was printed inside a :func:`captured_output` block (set when the block ends)."""

    text: str = ""


def _flush_c_stdio() -> None:
    """fflush(NULL): push C stdio buffers out before a descriptor is switched."""
    try:
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError):  # no C runtime reachable this way (not POSIX)
        pass


def _flush_all() -> None:
    for stream in (sys.stdout, sys.stderr):
        if stream is not None:
            stream.flush()
    _flush_c_stdio()


@contextmanager
def captured_output():
    """Redirect file descriptors 1 and 2 into a temporary file inside the block.

    Yields
    ------
    Captured
        Its ``text`` holds everything written to either descriptor (decoded as UTF-8, bad bytes
        replaced) once the block has ended, also when it ended with an exception.
    """
    captured = Captured()
    _flush_all()
    streams = sys.stdout, sys.stderr
    with tempfile.TemporaryFile() as sink:
        saved = [(fd, os.dup(fd)) for fd in _DESCRIPTORS]
        try:
            for fd in _DESCRIPTORS:
                os.dup2(sink.fileno(), fd)
            # Python-level prints (pybind11's py::print) go to the descriptors too, even where
            # sys.stdout was pointed elsewhere (answers_only_on_stdout).
            sys.stdout, sys.stderr = sys.__stdout__ or streams[0], sys.__stderr__ or streams[1]
            yield captured
        finally:
            _flush_all()
            sys.stdout, sys.stderr = streams
            for fd, copy in saved:
                os.dup2(copy, fd)
                os.close(copy)
            sink.seek(0)
            captured.text = sink.read().decode("utf-8", errors="replace")


@contextmanager
def answers_only_on_stdout():
    """Inside the block, whatever C code writes to file descriptor 1 (a solver's warning, an
    engine's banner) goes to stderr, while Python's ``sys.stdout`` still writes to the real
    standard output: a command's answer (``--json``) is then all that stdout receives.  Used
    around every command of the command line; C stdio buffers are flushed on the way out, before
    descriptor 1 is restored, so nothing written inside reaches stdout later.
    """
    _flush_all()
    real = sys.stdout
    saved = os.dup(1)
    if _descriptor(real) == 1:  # else sys.stdout writes elsewhere already (a test's capture)
        sys.stdout = open(saved, "w", encoding=getattr(real, "encoding", None) or "utf-8",
                          errors=getattr(real, "errors", None) or "strict",
                          buffering=1 if getattr(real, "line_buffering", False) else -1,
                          closefd=False)
    os.dup2(2, 1)
    try:
        yield
    finally:
        _flush_all()
        answers, sys.stdout = sys.stdout, real
        if answers is not real:
            answers.close()
        os.dup2(saved, 1)
        os.close(saved)


def _descriptor(stream) -> int | None:
    """The file descriptor ``stream`` writes to, or None (an in-memory stream)."""
    try:
        return stream.fileno()
    except (AttributeError, OSError, ValueError):
        return None


def engine_note(text: str, limit: int = NOTE_LIMIT) -> str | None:
    """A case note quoting what an engine printed, at most ``limit`` characters of it; None
    when it printed nothing but white space."""
    lines = [line.rstrip() for line in text.strip().splitlines() if line.strip()]
    if not lines:
        return None
    said = "\n".join(lines)
    if len(said) > limit:
        said = f"{said[:limit]} … ({len(said) - limit} more characters)"
    return f"the engine printed: {said}"
