"""Fixtures shared by every test folder: scenario variants written to temporary files.

Plain helpers (constants and functions that tests import) live in :mod:`tests.helpers`."""

from __future__ import annotations

from pathlib import Path

import pytest

from mbh._harness.model import scenario
from tests.helpers import variant_text


@pytest.fixture
def write_scenario(tmp_path: Path):
    """Write TOML text to ``tmp_path/<stem>.toml`` and return the path."""
    def write(stem: str, text: str) -> Path:
        path = tmp_path / f"{stem}.toml"
        path.write_text(text)
        return path
    return write


@pytest.fixture
def load_variant(write_scenario):
    """Load a shipped scenario with text edits applied."""
    def load(name: str, replacements: list[tuple[str, str]], stem: str | None = None):
        return scenario.load(write_scenario(stem or f"{name}_variant", variant_text(name, replacements)))
    return load
