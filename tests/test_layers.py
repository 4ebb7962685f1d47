"""The import rules of the project (docs/design.md, "Layers"), checked on every module of
``harness/``, ``adapters/`` and ``mbh/``.

Every ``import x`` and ``from x import y`` (module level and inside functions; relative imports
resolved against the importing package) is checked:

1. **Layers.** Each module belongs to one layer (:data:`LAYERS`, bottom first) and may import only
   the layers its entry lists, all of them below it: the harness's layers in the order of its data
   flow, with ``adapters`` between the measuring stick and the references.  A report reads the
   store only: it may not import the references, the runner or an adapter.
2. nothing outside ``adapters/inhouse/`` imports ``mbh._adapters.inhouse``;
3. ``harness/`` reaches adapters only through the registry: ``adapters`` and ``mbh._adapters.base``;
4. the contestants do not import the judge: of ``harness``, ``adapters/`` imports only
   :data:`ADAPTERS_MAY_IMPORT` (the model, the body graph, trajectories, statuses and the common
   start);
5. engine adapter packages (``adapters/*_adapter``) never import each other;
6. no import cycle among the modules (function-level imports included).

A failure names file:line and the import of every violation.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("harness", "adapters", "mbh")
#: The layers, bottom first: (name, module prefixes, layers it may import).
LAYERS = (
    ("common", ("mbh._harness.common",), ()),
    ("model", ("mbh._harness.model",), ("common",)),
    ("neutral", ("mbh._harness.neutral",), ("common", "model")),
    ("measure", ("mbh._harness.measure",), ("common", "model", "neutral")),
    ("store", ("mbh._harness.store",), ("common", "model")),
    ("adapters", ("mbh._adapters",), ("common", "model", "neutral")),
    ("references", ("mbh._harness.references",),
     ("common", "model", "neutral", "measure", "store", "adapters")),
    ("run", ("mbh._harness.run",),
     ("common", "model", "neutral", "measure", "store", "adapters", "references")),
    ("report", ("mbh._harness.report",), ("common", "model", "neutral", "measure", "store")),
    ("testing", ("mbh._harness.testing",),
     ("common", "model", "neutral", "measure", "store", "adapters", "references", "run")),
    ("jobs", ("mbh._harness.jobs",),
     ("common", "model", "neutral", "measure", "store", "adapters", "references", "run",
      "report")),
    ("cli", ("mbh._harness.cli", "mbh._harness"),
     ("common", "model", "neutral", "measure", "store", "adapters", "references", "run",
      "report", "testing", "jobs")),
    ("api", ("mbh",),
     ("common", "model", "neutral", "measure", "store", "adapters", "references", "run",
      "report", "testing", "jobs")),
)
_RANK = {name: rank for rank, (name, _, _) in enumerate(LAYERS)}
HARNESS_MAY_IMPORT = {"mbh._adapters", "mbh._adapters.base"}
ADAPTERS_MAY_IMPORT = {"mbh._harness.common", "mbh._harness.model.mechanism",
                       "mbh._harness.model.trajectory", "mbh._harness.model.topology",
                       "mbh._harness.neutral.start"}
#: The import package each repository folder is mapped to (pyproject.toml's package-dir).
MAPPED = {"harness": "mbh._harness", "adapters": "mbh._adapters", "mbh": "mbh"}


def module_name(path: Path) -> str:
    folder, *parts = path.relative_to(ROOT).with_suffix("").parts
    parts = [MAPPED[folder], *parts]
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


ENGINE_PACKAGES = {f"mbh._adapters.{path.name}"
                   for path in (ROOT / "adapters").glob("*_adapter")
                   if (path / "__init__.py").exists()}


def engine_package(name: str) -> str | None:
    """The engine adapter package (``adapters/*_adapter``) that ``name`` lies in, or None."""
    return next((package for package in ENGINE_PACKAGES if within(name, package)), None)


def layer(name: str) -> str | None:
    """The layer of module ``name`` (longest matching prefix), or None outside the project."""
    matches = [(len(prefix), layer_name) for layer_name, prefixes, _ in LAYERS
               for prefix in prefixes if within(name, prefix)]
    return max(matches)[1] if matches else None


def layer_violation(importer: str, imported: str) -> str | None:
    """Why the layer of ``importer`` may not import that of ``imported``, or None."""
    own, other = layer(importer), layer(imported)
    if own is None or other is None or own == other:
        return None
    allowed = dict((name, may) for name, _, may in LAYERS)[own]
    if other not in allowed:
        direction = "upward" if _RANK[other] > _RANK[own] else "across"
        return f"layer {own} may not import layer {other} ({direction}; it may import " \
               f"{', '.join(allowed) or 'nothing of the project'})"
    return None


def violation(importer: str, imported: str) -> str | None:
    """Why ``importer`` may not import ``imported``, or None."""
    reason = layer_violation(importer, imported)
    if reason:
        return reason
    if within(imported, "mbh._adapters.inhouse") and not within(importer, "mbh._adapters.inhouse"):
        return "only adapters/inhouse may import the in-house formulation"
    if within(importer, "mbh._harness") and within(imported, "mbh._adapters"):
        allowed = imported in HARNESS_MAY_IMPORT or any(
            imported.rpartition(".")[0] == package for package in HARNESS_MAY_IMPORT)
        if not allowed or engine_package(imported) or within(imported, "mbh._adapters.integrators"):
            return ("harness reaches adapters only through the registry (mbh._adapters, "
                    "mbh._adapters.base)")
    if within(importer, "mbh._adapters") and within(imported, "mbh._harness"):
        if imported != "mbh._harness" and not any(within(imported, m) for m in ADAPTERS_MAY_IMPORT):
            return ("adapters may import only " + ", ".join(sorted(ADAPTERS_MAY_IMPORT))
                    + ", not the measuring stick")
        if imported == "mbh._harness":
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


def test_the_layers_are_ordered_bottom_first():
    for name, _, may in LAYERS:
        assert all(_RANK[other] < _RANK[name] for other in may), name


def module_graph() -> dict[str, set[str]]:
    """Every project module and the project modules it imports (a ``from package import name``
    counts as importing ``package.name`` when that is a module, else ``package``)."""
    modules = {module_name(path): path for package in PACKAGES
               for path in (ROOT / package).rglob("*.py")}
    graph = {}
    for name, path in modules.items():
        edges = set()
        for _, imported, _ in imports(path):
            target = imported if imported in modules else imported.rpartition(".")[0]
            if target in modules and target != name:
                edges.add(target)
        graph[name] = edges
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []

    def visit(node):
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for other in graph[node]:
            if other not in index:
                visit(other)
                low[node] = min(low[node], low[other])
            elif other in on_stack:
                low[node] = min(low[node], index[other])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return found


def test_no_import_cycle():
    found = cycles(module_graph())
    assert not found, "import cycles:\n" + "\n".join(" <-> ".join(c) for c in found)


def test_the_cycle_finder_finds_a_cycle():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_the_layer_rule_refuses_upward_and_sideways_imports():
    assert "upward" in layer_violation("mbh._harness.measure.verdict", "mbh._harness.run.case.run_case")
    assert "upward" in layer_violation("mbh._harness.model.scenario", "mbh._harness.references.build")
    assert layer_violation("mbh._harness.report.build", "mbh._harness.references.build.reference_trajectory")
    assert layer_violation("mbh._harness.report.failures", "mbh._adapters.get_adapter")
    assert layer_violation("mbh._harness.store.runs", "mbh._harness.measure.metrics")
    assert layer_violation("mbh._harness.run.campaign", "mbh._harness.store.runs.RunStore") is None
    assert layer_violation("mbh._harness.cli", "mbh._harness.jobs.nightly") is None


def test_the_checker_sees_every_kind_of_violation():
    # The rules themselves, on the four forbidden patterns and their allowed neighbours.
    assert violation("mbh._adapters.pinocchio_adapter.adapter", "mbh._adapters.inhouse.bodies.constraints")
    assert violation("mbh._adapters.integrators.base", "mbh._adapters.inhouse.numerics.linalg.solve")
    assert violation("mbh._harness.measure.metrics", "mbh._adapters.inhouse.bodies.states.body_states")
    assert violation("mbh._harness.cli", "mbh._adapters.mujoco_adapter.export_mjcf")
    assert violation("mbh._harness.cli", "mbh._adapters.integrators.make_integrator")
    assert violation("mbh._adapters.inhouse.formulations.stabilisation", "mbh._harness.measure.energy.mechanical_energy")
    assert violation("mbh._adapters.mujoco_adapter.build", "mbh._harness.model.outputs")
    assert violation("mbh._adapters.mujoco_adapter.build", "mbh._adapters.pybullet_adapter.quiet")
    assert violation("mbh._adapters.inhouse.adapter", "mbh._adapters.inhouse.stepping.driver") is None
    assert violation("mbh._harness.cli", "mbh._adapters.get_adapter") is None
    assert violation("mbh._harness.cli", "mbh._adapters.base.UnsupportedCase") is None
    assert violation("mbh._adapters.pinocchio_adapter.adapter",
                     "mbh._adapters.integrators.IntegratorState") is None
    assert violation("mbh._adapters.base", "mbh._harness.common.status.CaseStatus") is None
    assert violation("mbh._adapters.mujoco_adapter.build", "mbh._harness.model.mechanism.Mechanism") is None
    assert violation("mbh._adapters.pinocchio_adapter.adapter", "mbh._adapters.pinocchio_adapter.build") \
        is None


def test_relative_and_function_level_imports_are_resolved(tmp_path, monkeypatch):
    package = tmp_path / "adapters" / "mujoco_adapter"
    package.mkdir(parents=True)
    (package / "__init__.py").write_text("")
    (package / "x.py").write_text("def f():\n    from ..inhouse import kernels\n"
                                  "    import mbh._harness.measure.energy\n")
    monkeypatch.setitem(globals(), "ROOT", tmp_path)
    found = list(imports(package / "x.py"))
    assert found[0][:2] == (2, "mbh._adapters.inhouse.kernels")
    assert found[1][:2] == (3, "mbh._harness.measure.energy")


#: The in-house formulation's tiers, bottom first (adapters/inhouse/<tier>/): a module may import
#: its own tier and the tiers below, never one above; the adapter module sits on top of them all.
INHOUSE_TIERS = ("numerics", "bodies", "formulations", "codegen", "stepping")


def inhouse_tier(name: str) -> int | None:
    """The rank of the in-house tier module ``name`` lies in, or None outside the tiers."""
    parts = name.split(".")
    if parts[:3] != ["mbh", "_adapters", "inhouse"] or len(parts) < 4:
        return None
    return INHOUSE_TIERS.index(parts[3]) if parts[3] in INHOUSE_TIERS else None


def test_the_inhouse_tiers_import_only_downward():
    found = []
    for path in sorted((ROOT / "adapters" / "inhouse").rglob("*.py")):
        importer = module_name(path)
        own = inhouse_tier(importer)
        for line, imported, written in imports(path):
            other = inhouse_tier(imported)
            if own is not None and other is not None and other > own:
                found.append(f"{path.relative_to(ROOT)}:{line}: {written} "
                             f"({INHOUSE_TIERS[own]} may not import {INHOUSE_TIERS[other]})")
    assert not found, "\n".join(found)
    assert all((ROOT / "adapters" / "inhouse" / tier / "__init__.py").is_file()
               for tier in INHOUSE_TIERS)
    assert inhouse_tier("mbh._adapters.inhouse.stepping.compiled") == 4
    assert inhouse_tier("mbh._adapters.inhouse.adapter") is None
