"""Fixtures shared by every test folder: scenario variants written to temporary files; the order
in which the test files run.

Plain helpers (constants and functions that tests import) live in :mod:`tests.helpers`."""

from __future__ import annotations

from pathlib import Path

import pytest

from mbh._harness.model import scenario
from tests.helpers import variant_text


#: Folders of tests/ whose files need, nearly all, no compiled kernel: they run first, so that
#: under ``mbh warm-up -- pytest`` (make test) the workers have work while the warm-up compiles,
#: and meet its gate (mbh._harness.common.warm_up_gate) as late as possible.  Measured in a
#: suite run on 2026-11-29: these files made no process load a kernel, but for a third of
#: tests/report's time.  A file placed wrongly only waits for the warm-up sooner.
KERNEL_FREE_FOLDERS = ("report", "cli", "model", "outside", "jobs", "acceptance", "measure",
                       "engines", "packaging")


def pytest_collection_modifyitems(items) -> None:
    """Files of :data:`KERNEL_FREE_FOLDERS` and the top-level files first, each group in its
    collected order (pytest-xdist's workers take whole files in this order: --dist loadfile)."""
    def late(item) -> bool:
        parts = Path(item.path).relative_to(Path(__file__).parent).parts
        return len(parts) > 1 and parts[0] not in KERNEL_FREE_FOLDERS

    items.sort(key=late)


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
