"""Griffe extension of the API pages (mkdocs.yml, mkdocstrings' python handler): the packages that
pyproject.toml's ``[tool.setuptools.package-dir]`` maps into ``mbh`` (harness/ → ``mbh._harness``,
adapters/ → ``mbh._adapters``) are loaded from their folders and set as members of ``mbh``.

Griffe finds a package's submodules in its own folder; mbh/ holds the public modules only, so
without this the names ``mbh``, ``mbh.adapters`` and ``mbh.testing`` re-export (aliases of the
private modules' objects) could not be resolved and rendered.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

import griffe

#: The project file holding the mapping, beside mkdocs.yml (``make docs`` runs from there).
PYPROJECT = Path("pyproject.toml")


class MappedPackages(griffe.Extension):
    """Loads each folder mapped to a direct subpackage of a loaded package and sets it as that
    package's member under its mapped name."""

    def on_package(self, *, pkg: griffe.Module, loader: griffe.GriffeLoader, **kwargs) -> None:
        mapping = tomllib.loads(PYPROJECT.read_text())["tool"]["setuptools"]["package-dir"]
        for dotted, folder in mapping.items():
            parent, _, name = dotted.rpartition(".")
            if parent != pkg.path or not (Path(folder) / "__init__.py").is_file():
                continue
            module = loader.load(Path(folder))
            loader.modules_collection.del_member(module.name)
            module.name = name
            pkg.set_member(name, module)
