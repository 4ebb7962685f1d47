"""The Python API page's examples (docs/api.md) run as written: every ```python block, in order,
in one namespace, in a fresh folder, with the results root and the reference cache in temporary
folders (the bar pendulum's reference is built there: ~10 s measured)."""

import re
from pathlib import Path

import pytest

PAGE = Path(__file__).resolve().parents[2] / "docs" / "api.md"


def blocks() -> list[str]:
    return re.findall(r"```python\n(.*?)```", PAGE.read_text(encoding="utf-8"), re.DOTALL)


def test_the_page_has_examples_for_every_task():
    text = "\n".join(blocks())
    for call in ("mbh.run_case(", "mbh.MechanismBuilder(", "mbh.run_campaign(", "mbh.load_run(",
                 "from mbh.adapters import", "from mbh.testing import"):
        assert call in text, call


def test_the_api_page_examples_run(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MBH_RESULTS_DIR", str(tmp_path / "results"))
    monkeypatch.setenv("MBH_CACHE_DIR", str(tmp_path / "references"))
    namespace: dict = {}
    for index, block in enumerate(blocks()):
        try:
            exec(compile(block, f"{PAGE}:block{index}", "exec"), namespace)
        except Exception as error:  # noqa: BLE001 — name the failing block
            pytest.fail(f"docs/api.md block {index} failed: {error!r}\n{block}")
