"""The wheel installs one import package, ``mbh``, so it sits beside PyPI's unrelated packages named
``adapters`` (AdapterHub) and ``harness`` (slow: the fresh environment of
tests/packaging/conftest.py, and a download of AdapterHub's wheel from PyPI).

Before the one package, ``pip install --no-deps adapters==1.3.0`` overwrote the harness's
``adapters/__init__.py`` and broke every command; ``pip uninstall adapters`` then deleted it.
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import pytest

from tests.packaging.conftest import run

pytestmark = pytest.mark.slow

#: AdapterHub's release named in the report of the clash; installed without its dependencies
#: (torch, transformers), so importing its modules beyond the package is not tried.
NAMESAKE = "adapters==1.3.0"


def test_the_wheel_records_only_the_mbh_package(installed):
    bin_folder, _, _ = installed
    wheel, = (bin_folder.parent.parent / "dist").glob("mbh-*.whl")
    with zipfile.ZipFile(wheel) as archive:
        record = next(name for name in archive.namelist() if name.endswith(".dist-info/RECORD"))
        files = [line.split(",")[0] for line in archive.read(record).decode().splitlines()]
    strays = [name for name in files
              if not (name.startswith("mbh/") or name.split("/")[0].startswith("mbh-"))]
    assert files and not strays, strays
    assert "mbh/_harness/scenarios/fourbar.toml" in files


def _adapter_names(bin_folder, user, env) -> list[str]:
    return [row["name"] for row in
            json.loads(run([bin_folder / "mbh", "adapters", "--json"], user, env).stdout)]


def test_mbh_works_beside_adapterhub_and_after_it_is_uninstalled(installed):
    bin_folder, user, env = installed
    python = bin_folder / "python"
    run([python, "-m", "pip", "install", "-q", "--no-deps", NAMESAKE], user, env)
    try:
        # AdapterHub's package imports torch, not installed here: find it without running it.
        where = run([python, "-c", "import importlib.util; "
                     "print(importlib.util.find_spec('adapters').origin)"], user, env)
        origin = Path(where.stdout.strip())
        assert origin.parts[-3:] == ("site-packages", "adapters", "__init__.py")
        assert "MultiTaskConfig" in origin.read_text()  # AdapterHub's, not a file of mbh's
        done = run([bin_folder / "mbh", "simulate", "fourbar", "--adapter", "mujoco", "--method",
                    "best", "--dt", "1e-3", "--json"], user, env)
        assert json.loads(done.stdout)["status"] == "ok"
        assert _adapter_names(bin_folder, user, env) == ["inhouse", "mujoco", "pybullet",
                                                         "pinocchio", "exudyn", "toy"]
    finally:
        run([python, "-m", "pip", "uninstall", "-q", "-y", "adapters"], user, env)
    run([python, "-c", "import mbh, mbh.adapters"], user, env)
    assert "toy" in _adapter_names(bin_folder, user, env)
