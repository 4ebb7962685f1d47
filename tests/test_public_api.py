"""The public API is three modules, ``mbh``, ``mbh.adapters`` and ``mbh.testing``: their names are
pinned here, so a change to the contract is a deliberate one (change the sets below with it, and
say so in the docs); and what the documentation tells a user to import comes from them alone.
"""

from __future__ import annotations

import importlib
import re

import pytest

from tests.helpers import ROOT

#: Every public name, by module.
PUBLIC = {
    "mbh": {
        "Bounds", "CampaignError", "CaseInputError", "CaseResult", "MbhError", "Mechanism",
        "MechanismBuilder", "RunStore", "ScenarioError", "campaign_names", "compare_runs",
        "list_runs", "load_campaign", "load_run", "load_scenario", "results_root",
        "run_campaign", "run_case", "scenario_names",
    },
    "mbh.adapters": {
        "ENTRY_POINT_GROUP", "GROUND", "UNCLOSABLE", "Adapter", "AdapterChoiceError",
        "AdapterLoadError", "Body", "BodyForce", "BodyStates", "BodyTorque", "Joint",
        "JointActuation", "Mechanism", "MethodSpec", "RunFailure", "RunGrid", "SpanningTree",
        "SpringDamper", "Stepper", "SystemGraph", "UnknownAdapterError", "UnsupportedCase",
        "adapter_names", "get_adapter", "initial_state", "spanning_tree", "system_graph",
    },
    "mbh.testing": {
        "CaseRunner", "CaseTolerance", "OutputTolerance", "SessionCase", "ToleranceError",
        "Tolerances", "assert_at_least_as_fast", "assert_close_to_reference",
        "assert_constraint_violation_below", "assert_convergence_order",
        "assert_energy_error_below", "assert_status", "assert_within_tolerance",
        "campaign_params", "case_spec", "constraint_violation_series", "convergence_order",
        "energy_error_series",
    },
}

#: The pages a user reads: every documentation page and the README.
PAGES = sorted((ROOT / "docs").rglob("*.md")) + [ROOT / "README.md"]
#: Top-level packages that are this project's: an import from them must be a public module.
OURS = ("mbh", "harness", "adapters")


@pytest.mark.parametrize("module", sorted(PUBLIC))
def test_the_public_names_are_exactly_the_pinned_ones(module):
    public = importlib.import_module(module)
    assert len(public.__all__) == len(set(public.__all__))
    assert set(public.__all__) == PUBLIC[module]
    for name in public.__all__:
        assert getattr(public, name) is not None


def imported_modules(code: str) -> list[str]:
    """The modules a block of Python code imports from (``import X``, ``from X import ...``)."""
    return re.findall(r"^\s*(?:from\s+([\w.]+)\s+import|import\s+([\w.]+))", code, re.MULTILINE)


def test_the_documentation_imports_the_public_modules_only():
    private = []
    for page in PAGES:
        for block in re.findall(r"```python\n(.*?)```", page.read_text(encoding="utf-8"),
                                re.DOTALL):
            for module in (name for pair in imported_modules(block) for name in pair if name):
                if module.split(".")[0] in OURS and module not in PUBLIC:
                    private.append(f"{page.relative_to(ROOT)}: {module}")
    assert private == []


def test_the_check_sees_a_private_import():
    assert imported_modules("import mbh\nfrom mbh._harness.run.row import run_spec\n") == [
        ("", "mbh"), ("mbh._harness.run.row", "")]
