"""Waits said aloud (harness/common/waits.py): the command line's stderr lines, and the handler
that shows them."""

from __future__ import annotations

import io
import sys

from mbh._harness.common import waits


def test_a_wait_is_said_before_and_its_length_after(monkeypatch):
    stream = io.StringIO()
    monkeypatch.setattr(sys, "stderr", stream)
    monkeypatch.setattr(waits, "QUIET_BELOW_S", 0.0)
    waits.show_on_stderr()
    with waits.said("compiling something", "once on this machine", 150.0):
        pass
    lines = stream.getvalue().splitlines()
    assert lines[0] == "mbh: compiling something (once on this machine, ~2 min) …"
    assert lines[1].startswith("mbh: compiling something: done in ")


def test_quiet_says_nothing(monkeypatch):
    stream = io.StringIO()
    monkeypatch.setattr(sys, "stderr", stream)
    waits.show_on_stderr(quiet=True)
    with waits.said("compiling something"):
        pass
    assert stream.getvalue() == ""


def test_a_second_call_never_closes_a_stream_it_did_not_open(monkeypatch):
    """A test's captured stderr (no descriptor) is written to as it is, and left open when the
    next command replaces the handler: closing it broke pytest's capture of a later test."""
    first, second = io.StringIO(), io.StringIO()
    monkeypatch.setattr(sys, "stderr", first)
    waits.show_on_stderr()
    monkeypatch.setattr(sys, "stderr", second)
    waits.show_on_stderr()
    waits.LOG.info("hello")
    assert not first.closed and "mbh: hello" in second.getvalue()
