"""Shared test helpers: scenario variants written to temporary files."""

from __future__ import annotations

from pathlib import Path

import pytest

from harness import scenario

#: Scenes with a shipped verified reference and the seed's outputs (crank_angle, driver "O"); the
#: engine accuracy tables below are measured on them.  ``double_fourbar`` is not among them: its
#: reference build is refused (the routes disagree by 1.2e-4 m at its singular passages).
VERIFIED_SCENES = ("fourbar", "fourbar_spatial", "slider_crank", "slider_crank_planar")


def variant_text(name: str, replacements: list[tuple[str, str]]) -> str:
    """The shipped scenario ``name`` with each ``old`` text replaced by ``new`` (must occur)."""
    text = scenario.scenario_path(name).read_text()
    for old, new in replacements:
        assert old in text, f"fixture edit {old!r} not found in {name}.toml"
        text = text.replace(old, new)
    return text


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
