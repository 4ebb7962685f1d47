"""Third-party adapters registered without pip: a distribution's metadata (``NAME-VERSION.dist-info``
with ``METADATA`` and ``entry_points.txt``) written into a temporary folder on ``sys.path`` (or
on ``PYTHONPATH`` for a subprocess) is what ``importlib.metadata.entry_points`` reads for an
installed package, so the registry finds it as it finds a pip-installed one.

The toy adapter package is the one the adapter guide (docs/adapter-contract.md, "A complete
example") prints: its files are written from the guide's blocks as they stand, and registered from
its own ``pyproject.toml`` (name, version, entry points).  The user's test file that holds it to
the reference is the guide's too ("Using it").
"""

from __future__ import annotations

import os
import sys
import tomllib
from pathlib import Path

import pytest

from tests.helpers import ROOT, page_files

#: The adapter guide, which holds the toy adapter package and a user's test file of it.
GUIDE = ROOT / "docs" / "adapter-contract.md"
#: The toy package's files (path → text), from the guide.
TOY_FILES = page_files(GUIDE, "## A complete example")
#: A user's test file holding the toy adapter to the reference through the plugin, from the guide.
USER_TEST = page_files(GUIDE, "## Using it")["test_my_solver.py"]


def write_toy_package(folder: Path) -> Path:
    """Write the toy adapter package's source (its pyproject.toml and module) into ``folder``;
    returns ``folder``, which holds the importable module ``mbh_toy_adapter``."""
    for name, text in TOY_FILES.items():
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        (folder / name).write_text(text, encoding="utf-8")
    return folder


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
    return tomllib.loads(TOY_FILES["pyproject.toml"])["project"]


@pytest.fixture(scope="session")
def toy_source(tmp_path_factory) -> Path:
    """The toy package's source folder, written from the guide once per session."""
    return write_toy_package(tmp_path_factory.mktemp("toy") / "mbh_toy_adapter")


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
def toy_module(toy_source, monkeypatch, forget_modules) -> Path:
    """The toy package's module importable in this process for one test, not registered;
    returns its source folder."""
    monkeypatch.syspath_prepend(str(toy_source))
    forget_modules("mbh_toy_adapter")
    return toy_source


@pytest.fixture
def toy(toy_module, toy_folder, monkeypatch) -> Path:
    """The toy adapter registered in this process for one test; returns the metadata folder,
    where a test may write more distributions and modules."""
    monkeypatch.syspath_prepend(str(toy_folder))
    return toy_folder


@pytest.fixture
def toy_environment(toy_folder, toy_source) -> dict:
    """An environment for a subprocess in which the toy adapter is registered."""
    paths = [str(toy_folder), str(toy_source), os.environ.get("PYTHONPATH", "")]
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
