"""Files kept by the warm template (mbh._harness.common.kept_files): kept only inside ``keeping()``,
returned while the files are unchanged, read again once a file is replaced or rewritten."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from mbh._harness.common.kept_files import identity, keeping, read_kept


class _Reader:
    """Reads a text file and counts its reads."""

    def __init__(self, path):
        self.path, self.reads = path, 0

    def __call__(self):
        self.reads += 1
        return self.path.read_text()


def test_a_read_outside_keeping_is_never_kept(tmp_path):
    path = tmp_path / "a.txt"
    path.write_text("one")
    read = _Reader(path)
    assert read_kept("test-outside", (path,), read) == "one"
    assert read_kept("test-outside", (path,), read) == "one"
    assert read.reads == 2


def test_a_kept_read_is_returned_until_the_file_is_replaced_or_rewritten(tmp_path):
    path = tmp_path / "a.txt"
    path.write_text("one")
    read = _Reader(path)
    with keeping():
        first = read_kept("test-kept", (path,), read)
    assert read_kept("test-kept", (path,), read) is first and read.reads == 1

    replacement = tmp_path / "b.txt"  # as the project writes: a new file moved into place
    replacement.write_text("two")
    os.replace(replacement, path)
    assert read_kept("test-kept", (path,), read) == "two" and read.reads == 2

    path.write_text("three, longer")  # rewritten in place, to another size
    assert read_kept("test-kept", (path,), read) == "three, longer" and read.reads == 3


def test_a_kind_is_kept_apart_from_another_of_the_same_file(tmp_path):
    path = tmp_path / "a.txt"
    path.write_text("one")
    with keeping():
        read_kept("test-kind-a", (path,), lambda: "as a")
    assert read_kept("test-kind-b", (path,), lambda: "as b") == "as b"


def test_a_failed_read_or_a_missing_file_is_not_kept(tmp_path):
    path, missing = tmp_path / "a.txt", tmp_path / "missing.txt"
    path.write_text("one")

    def broken():
        raise ValueError("unreadable")

    with keeping():
        with pytest.raises(ValueError):
            read_kept("test-failed", (path,), broken)
        assert read_kept("test-failed", (path, missing), lambda: "without") == "without"
    assert read_kept("test-failed", (path,), lambda: "read") == "read"
    assert read_kept("test-failed", (path, missing), lambda: "again") == "again"


def test_a_name_the_system_refuses_has_no_identity_and_is_read():
    assert identity(Path("\x00.toml")) is None
    assert read_kept("test-refused", (Path("\x00.toml"),), lambda: "read") == "read"
