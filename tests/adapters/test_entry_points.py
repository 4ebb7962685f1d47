"""Third-party adapters through the entry-point group ``mbh.adapters``: discovered next to the
built-in engines without importing any engine, listed by ``mbh adapters`` with their origin,
named in campaign files and ``--mbh-adapters``, run, judged and reported like a built-in engine.

The toy adapter (the adapter guide's package, written against ``mbh.adapters`` alone) is
registered through a temporary dist-info folder (tests/adapters/conftest.py).
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

import mbh._adapters as adapters
from mbh._adapters import AdapterClashWarning, UnknownAdapterError
from mbh._harness.cli import main
from mbh._harness.measure.verdict import DEFAULT_ACCURACY, DEFAULT_BOUNDS
from mbh._harness.report import summary
from mbh._harness.run.row import run_spec
from mbh._harness.run.spec import CampaignError, CaseSpec, load_campaign
from mbh._harness.store.runs import RunStore
from mbh._harness.testing.cases import Selection, ToleranceError
from tests.adapters.conftest import USER_TEST, toy_project, write_distribution

TOY_PACKAGE = f"{toy_project()['name']} {toy_project()['version']}"

CAMPAIGN = """\
description = "the toy adapter next to a built-in engine"
calibration = false

[t_end]
"*" = 0.2

[[group]]
scenarios = ["fourbar"]
adapters = ["inhouse", "toy"]
methods = ["best"]
dts = [1e-3]

[[group]]
scenarios = ["fourbar_spatial"]
adapters = ["toy"]
methods = ["best"]
dts = [1e-2]
"""


def test_listing_the_adapters_imports_no_engine(toy_environment):
    probe = ("import sys, mbh._adapters as adapters; names = adapters.adapter_names(); "
             "print(names); print(sorted(m for m in sys.modules if m.split('.')[0] in "
             "('mujoco', 'pybullet', 'pinocchio', 'exudyn', 'mbh_toy_adapter') "
             "or m.startswith('mbh._adapters.')))")
    done = subprocess.run([sys.executable, "-c", probe], env=toy_environment,
                          capture_output=True, text=True, timeout=60, check=True)
    names, imported = done.stdout.splitlines()
    assert names == str([*adapters.BUILT_IN, "toy"])
    assert imported == "['mbh._adapters.base']"


def test_the_toy_adapter_is_registered_with_its_package(toy):
    assert adapters.adapter_names() == [*adapters.BUILT_IN, "toy"]
    found = adapters.registration("toy")
    assert (found.origin, found.package_version, found.built_in) == ("mbh-toy-adapter", "0.1.0",
                                                                     False)
    adapter = adapters.get_adapter("toy")
    assert (adapter.name, adapter.package, adapter.version()) == ("toy", TOY_PACKAGE, "toy 0.1.0")
    assert adapters.get_adapter("mujoco").package == ""


def test_without_the_entry_point_the_name_is_unknown():
    with pytest.raises(UnknownAdapterError, match="unknown adapter 'toy'; valid: inhouse, mujoco"):
        adapters.get_adapter("toy")


def test_mbh_adapters_lists_origin_and_versions(toy, capsys):
    assert main(["adapters", "--json"]) == 0
    rows = {row["name"]: row for row in json.loads(capsys.readouterr().out)}
    assert list(rows) == [*adapters.BUILT_IN, "toy"]
    assert rows["toy"] == {"name": "toy", "origin": "mbh-toy-adapter", "package_version": "0.1.0",
                           "version": "toy 0.1.0", "methods": 2, "problem": ""}
    assert rows["mujoco"]["origin"] == "built-in" and rows["mujoco"]["package_version"] is None
    assert main(["adapters"]) == 0
    line = next(text for text in capsys.readouterr().out.splitlines() if text.startswith("toy"))
    assert line.split() == ["toy", "mbh-toy-adapter", "0.1.0", "toy", "0.1.0", "2"]


def test_a_built_in_name_wins_a_clash_and_the_clash_is_reported(toy, capsys):
    write_distribution(toy, "mbh-impostor", "2.0", {"mujoco": "mbh_toy_adapter:ToyAdapter"})
    write_distribution(toy, "zz-late-toy", "1.0", {"toy": "mbh_toy_adapter:ToyAdapter"})
    with pytest.warns(AdapterClashWarning) as caught:
        assert adapters.adapter_names() == [*adapters.BUILT_IN, "toy"]
    assert sorted(str(w.message) for w in caught) == [
        "adapter 'mujoco' from package mbh-impostor 2.0 is ignored: the name belongs to the "
        "adapter 'mujoco' (built-in)",
        "adapter 'toy' from package zz-late-toy 1.0 is ignored: the name belongs to the adapter "
        f"'toy' from package {TOY_PACKAGE}"]
    with pytest.warns(AdapterClashWarning):
        assert adapters.registration("mujoco").built_in
        assert adapters.registration("toy").origin == "mbh-toy-adapter"
    with pytest.warns(AdapterClashWarning):
        assert main(["adapters", "--json"]) == 1  # an ignored entry point is a problem row
    rows = json.loads(capsys.readouterr().out)
    assert [(row["name"], row["origin"]) for row in rows[-2:]] == [("mujoco", "mbh-impostor"),
                                                                  ("toy", "zz-late-toy")]
    assert all("is ignored" in row["problem"] for row in rows[-2:])


def test_a_toy_case_is_run_and_judged_as_an_engine_case(toy):
    row = run_spec(CaseSpec("fourbar", "toy", "best", 1e-3, 0.5), DEFAULT_BOUNDS,
                   DEFAULT_ACCURACY).row
    assert (row["status"], row["reason"], row["accurate"]) == ("ok", "", True)
    # Measured: crank angle 4.7e-9 rad from the reference over 0.5 s (RK4, dt 1e-3 s; 8.0e-8 rad
    # over the full 4 s); bound 100 times that.
    assert row["main_output_error"] < 4.7e-7
    assert row["adapter_version"] == "toy 0.1.0"
    assert json.loads(row["packages"])["adapter_package"] == TOY_PACKAGE
    assert (row["n_coordinates"], row["n_constraint_equations"], row["n_redundant_equations"]) \
        == (9, 8, 0)
    spatial = run_spec(CaseSpec("fourbar_spatial", "toy", "best", 1e-2, 0.1), DEFAULT_BOUNDS,
                       DEFAULT_ACCURACY).row
    assert (spatial["status"], spatial["reason"]) == (
        "unsupported", "the toy adapter models planar mechanisms only")


def test_a_campaign_file_names_it_and_its_methods_are_checked(toy, tmp_path):
    path = tmp_path / "with_toy.toml"
    path.write_text(CAMPAIGN)
    cases = load_campaign(path).cases
    assert [(c.scenario, c.adapter) for c in cases] == [
        ("fourbar", "inhouse"), ("fourbar", "toy"), ("fourbar_spatial", "toy")]
    path.write_text(CAMPAIGN.replace('["toy"]\nmethods = ["best"]', '["toy"]\nmethods = ["rk9"]'))
    with pytest.raises(CampaignError, match=r"group\[1\]\.methods\[0\]: unknown toy method "
                                            r"'rk9'; valid: default, best"):
        load_campaign(path)


def test_the_plugin_selects_it_by_name(toy):
    assert Selection.parse(None, "toy,mujoco").adapters == {"toy", "mujoco"}
    with pytest.raises(ToleranceError, match="--mbh-adapters: unknown toyy"):
        Selection.parse(None, "toyy")


def test_the_reports_tables_treat_it_as_an_engine(toy, tmp_path):
    path = tmp_path / "with_toy.toml"
    path.write_text(CAMPAIGN)
    campaign = load_campaign(path)
    store = RunStore.create(campaign, tmp_path / "results")
    for spec in campaign.cases:
        result = run_spec(spec, DEFAULT_BOUNDS, DEFAULT_ACCURACY)
        store.add(result.row, result.trajectory)
    store.finish("complete")
    cases = store.cases()
    assert [row[:2] for row in summary.status_counts_table(cases).rows] == [
        ("fourbar", "inhouse"), ("fourbar", "toy"), ("fourbar_spatial", "toy")]
    assert [row[:3] for row in summary.failures_table(cases).rows] == [
        ("fourbar_spatial", "toy", "best")]
    assert [row[:5] for row in summary.model_size_table(cases, 1e-3).rows if row[1] == "toy"] \
        == [("fourbar", "toy", 9, 8, 0), ("fourbar_spatial", "toy", None, None, None)]
    # The in-house front is set against the engines': the toy is one (measured crank-angle
    # errors at 0.2 s: toy 1.4e-11 rad, in-house 3.7e-14 rad, both within the level 1e-6).
    front = summary.front_ratio_table(cases, "fourbar", levels=(1e-6,)).rows
    assert front[0][4:6] == ("toy", "best")


def test_a_user_test_file_asserts_on_it_through_the_plugin(toy_environment, tmp_path):
    (tmp_path / "test_my_solver.py").write_text(USER_TEST)
    done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                           "--mbh-adapters", "toy"], cwd=tmp_path, env=toy_environment,
                          capture_output=True, text=True, timeout=300, check=False)
    assert "1 passed" in done.stdout, done.stdout + done.stderr
