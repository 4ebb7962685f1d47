"""Third-party adapters registered without pip: a distribution's metadata (``NAME-VERSION.dist-info``
with ``METADATA`` and ``entry_points.txt``) written into a temporary folder on ``sys.path`` (or
on ``PYTHONPATH`` for a subprocess) is what ``importlib.metadata.entry_points`` reads for an
installed package, so the registry finds it as it finds a pip-installed one.

The toy adapter package (tests/data/mbh_toy_adapter) is registered from its own
``pyproject.toml``: its name, version and entry points.
"""

from __future__ import annotations

import os
import sys
import tomllib
from pathlib import Path

import pytest

from tests.helpers import ROOT

#: The third-party adapter package of the tests, source folder (its pyproject.toml beside).
TOY = ROOT / "tests" / "data" / "mbh_toy_adapter"

#: A user's test file holding the toy adapter to the reference through the plugin.
USER_TEST = """\
from mbh._harness.testing.tolerances import assert_close_to_reference, assert_status


def test_my_solver_on_the_fourbar(mbh_runner):
    result = mbh_runner.case("fourbar", "toy", "best", dt=1e-3, t_end=0.5)
    assert_status(result)
    assert_close_to_reference(result, "crank_angle", atol=1e-7)  # measured 4.7e-9 rad
"""


def write_distribution(folder: Path, name: str, version: str, adapters: dict[str, str]) -> None:
    """Write the metadata of distribution ``name`` ``version`` declaring ``adapters``
    (adapter name → ``module:Class``) in the entry-point group ``mbh.adapters`` into ``folder``."""
    info = folder / f"{name.replace('-', '_')}-{version}.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: {version}\n")
    lines = [f"{adapter} = {target}" for adapter, target in adapters.items()]
    (info / "entry_points.txt").write_text("[mbh.adapters]\n" + "\n".join(lines) + "\n")


def toy_project() -> dict:
    """The ``[project]`` table of the toy package's pyproject.toml."""
    return tomllib.loads((TOY / "pyproject.toml").read_text())["project"]


@pytest.fixture
def toy_folder(tmp_path) -> Path:
    """A folder holding the toy package's distribution metadata (put it and :data:`TOY` on the
    path to register the toy adapter)."""
    project = toy_project()
    folder = tmp_path / "site"
    write_distribution(folder, project["name"], project["version"],
                       project["entry-points"]["mbh.adapters"])
    return folder


@pytest.fixture
def toy(toy_folder, monkeypatch) -> Path:
    """The toy adapter registered in this process for one test; returns the metadata folder,
    where a test may write more distributions and modules."""
    monkeypatch.syspath_prepend(str(TOY))
    monkeypatch.syspath_prepend(str(toy_folder))
    return toy_folder


@pytest.fixture
def toy_environment(toy_folder) -> dict:
    """An environment for a subprocess in which the toy adapter is registered."""
    paths = [str(toy_folder), str(TOY), os.environ.get("PYTHONPATH", "")]
    return {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, paths))}


@pytest.fixture
def forget_modules():
    """``forget_modules(*names)``: drop modules a test imports from its temporary folder out of
    ``sys.modules`` at teardown (the next test writes its own under the same names)."""
    names = []

    def forget(*modules: str) -> None:
        names.extend(modules)

    yield forget
    for name in names:
        sys.modules.pop(name, None)
