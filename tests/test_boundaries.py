"""The import boundaries of DESIGN.md, checked on every module of harness/ and adapters/.

Every ``import x`` and ``from x import y`` (module level and inside functions; relative imports
resolved against the importing package) is checked against four rules:

1. nothing outside ``adapters/inhouse/`` imports ``adapters.inhouse``;
2. ``harness/`` reaches adapters only through the registry: ``adapters`` and ``adapters.base``;
3. nothing in ``adapters/`` imports the measuring stick: of ``harness`` only ``harness.model``,
   ``harness.trajectory``, ``harness.topology`` and ``harness.initial`` (the common start);
4. engine adapter packages (``adapters/*_adapter``) never import each other.

A failure names file:line and the import of every violation.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("harness", "adapters")
HARNESS_MAY_IMPORT = {"adapters", "adapters.base"}
ADAPTERS_MAY_IMPORT = {"harness.model", "harness.trajectory", "harness.topology",
                       "harness.initial"}


def module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports(path: Path):
    """(line, imported module, as written) for every import in ``path``.

    ``from package import name`` yields ``package.name`` (a submodule or an attribute: both are
    held to the rules, which are about packages).
    """
    package = module_name(path)
    if path.name != "__init__.py":
        package = package.rpartition(".")[0]
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name, f"import {alias.name}"
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")
                anchor = anchor[:len(anchor) - node.level + 1]
                base = ".".join([*anchor, base] if base else anchor)
            written = f"from {'.' * node.level}{node.module or ''} import " \
                      f"{', '.join(a.name for a in node.names)}"
            for alias in node.names:
                yield node.lineno, f"{base}.{alias.name}", written


def within(name: str, package: str) -> bool:
    return name == package or name.startswith(package + ".")


ENGINE_PACKAGES = {f"adapters.{path.name}" for path in (ROOT / "adapters").glob("*_adapter")
                   if (path / "__init__.py").exists()}


def engine_package(name: str) -> str | None:
    """The engine adapter package (``adapters/*_adapter``) that ``name`` lies in, or None."""
    return next((package for package in ENGINE_PACKAGES if within(name, package)), None)


def violation(importer: str, imported: str) -> str | None:
    """Why ``importer`` may not import ``imported``, or None."""
    if within(imported, "adapters.inhouse") and not within(importer, "adapters.inhouse"):
        return "only adapters/inhouse may import the in-house formulation"
    if within(importer, "harness") and within(imported, "adapters"):
        allowed = imported in HARNESS_MAY_IMPORT or any(
            imported.rpartition(".")[0] == package for package in HARNESS_MAY_IMPORT)
        if not allowed or engine_package(imported) or imported.startswith("adapters.integrators"):
            return "harness reaches adapters only through the registry (adapters, adapters.base)"
    if within(importer, "adapters") and within(imported, "harness"):
        if imported != "harness" and not any(within(imported, m) for m in ADAPTERS_MAY_IMPORT):
            return ("adapters may import only harness.model, harness.trajectory, "
                    "harness.topology and harness.initial, not the measuring stick")
        if imported == "harness":
            return "adapters may not import the harness package wholesale"
    own, other = engine_package(importer), engine_package(imported)
    if own and other and own != other:
        return "engine adapters never import each other"
    return None


def violations() -> list[str]:
    found = []
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            importer = module_name(path)
            for line, imported, written in imports(path):
                reason = violation(importer, imported)
                if reason:
                    found.append(f"{path.relative_to(ROOT)}:{line}: {written}  ({reason})")
    return found


def test_imports_respect_the_boundaries():
    found = violations()
    assert not found, "import boundary violations:\n" + "\n".join(found)


def test_the_checker_sees_every_kind_of_violation():
    # The rules themselves, on the four forbidden patterns and their allowed neighbours.
    assert violation("adapters.pinocchio_adapter.adapter", "adapters.inhouse.constraints")
    assert violation("adapters.integrators.base", "adapters.inhouse.linalg.solve")
    assert violation("harness.metrics", "adapters.inhouse.states.body_states")
    assert violation("harness.cli", "adapters.mujoco_adapter.export_mjcf")
    assert violation("harness.cli", "adapters.integrators.make_integrator")
    assert violation("adapters.inhouse.stabilisation", "harness.energy.mechanical_energy")
    assert violation("adapters.mujoco_adapter.build", "harness.outputs")
    assert violation("adapters.mujoco_adapter.build", "adapters.pybullet_adapter.quiet")
    assert violation("adapters.inhouse.adapter", "adapters.inhouse.driver") is None
    assert violation("harness.cli", "adapters.get_adapter") is None
    assert violation("harness.cli", "adapters.base.UnsupportedCase") is None
    assert violation("adapters.pinocchio_adapter.adapter", "adapters.integrators.RUNNING") is None
    assert violation("adapters.mujoco_adapter.build", "harness.model.Mechanism") is None
    assert violation("adapters.pinocchio_adapter.adapter", "adapters.pinocchio_adapter.build") \
        is None


def test_relative_and_function_level_imports_are_resolved(tmp_path, monkeypatch):
    package = tmp_path / "adapters" / "mujoco_adapter"
    package.mkdir(parents=True)
    (package / "__init__.py").write_text("")
    (package / "x.py").write_text("def f():\n    from ..inhouse import kernels\n"
                                  "    import harness.energy\n")
    monkeypatch.setitem(globals(), "ROOT", tmp_path)
    found = list(imports(package / "x.py"))
    assert found[0][:2] == (2, "adapters.inhouse.kernels")
    assert found[1][:2] == (3, "harness.energy")
