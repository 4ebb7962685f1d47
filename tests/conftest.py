"""Shared test helpers: scenario variants written to temporary files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from harness.model import scenario

GRAVITY = 9.81  # m/s², double_fourbar's gravity

#: Scenes with a shipped verified reference and the seed's outputs (crank_angle, driver "O"); the
#: engine accuracy tables below are measured on them.  ``double_fourbar`` (verified along its
#: declared branch) has other outputs and is checked in test_double_fourbar/test_branch_route.
VERIFIED_SCENES = ("fourbar", "fourbar_spatial", "slider_crank", "slider_crank_planar")


def reduced_tip(times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tip (x, y) of ``double_fourbar``'s first crank from its one-degree-of-freedom model
    3 φ̈ = −3.5 g cos φ (derived in tests/test_double_fourbar.py), shape (n,) each, m."""
    def rhs(_t, state):
        return [state[1], -(3.5 / 3.0) * GRAVITY * np.cos(state[0])]

    solution = solve_ivp(rhs, (0.0, times[-1]), [np.pi / 2, -1.0], method="DOP853",
                         rtol=1e-13, atol=1e-13, t_eval=times)
    return np.cos(solution.y[0]), np.sin(solution.y[0])


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
