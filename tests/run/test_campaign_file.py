"""Campaign files: validation (every mistake at once, with file and field), deterministic expansion,
and the shipped campaigns."""

from __future__ import annotations

import math

import pytest

from mbh._adapters import adapter_names
from mbh._harness.run import spec as campaign
from mbh._harness.model import scenario
from mbh._harness.run.spec import CampaignError, CaseSpec, load_campaign, main_output
from mbh._harness.measure.verdict import Bounds

#: A file with one mistake per line that matters; each (field, words of the message) must be named.
BAD = """
colour = "blue"
repetitions = 0
timeout_s = -5.0
accuracy = "tight"
calibration = "yes"

[bounds]
gap = -1.0
wobble = 2.0

[t_end]
fourbar = 100.0
nowhere = 1.0

[[group]]
scenarios = ["fourbar", "no_such_scene"]
adapters = ["mujoco", "no_such_engine"]
methods = ["best", "warp-drive", "default:no_such_param=1"]
dts = [-1e-3, 3e-3, nan, "fast"]
speed = 1

[[group]]
scenarios = ["fourbar"]
adapters = ["inhouse"]
methods = ["rk4+direct"]
dts = [1e-2]
t_end = { fourbar = 0.105 }

[sweep]
scenarios = "all"
adapters = ["inhouse"]
methods = ["rk4+none"]
dt_min = 1e-2
dt_max = 1e-3
"""

EXPECTED_PROBLEMS = [
    ("colour", "unknown key"),
    ("repetitions", "integer >= 1"),
    ("timeout_s", "must be > 0"),
    ("accuracy", "finite number"),
    ("calibration", "true or false"),
    ("bounds.gap", "must be > 0"),
    ("bounds.wobble", "unknown key"),
    ("t_end.fourbar", "beyond the scenario's duration"),
    ("t_end.nowhere", "unknown scenario"),
    ("group[0].scenarios[1]", "unknown scenario 'no_such_scene'"),
    ("group[0].adapters[1]", "unknown adapter 'no_such_engine'"),
    ("group[0].methods[1]", "unknown mujoco method 'warp-drive'"),
    ("group[0].methods[2]", "no parameter no_such_param"),
    ("group[0].dts[0]", "finite step > 0"),
    ("group[0].dts[1]", "does not divide the evaluation grid step"),
    ("group[0].dts[2]", "finite step > 0"),
    ("group[0].dts[3]", "finite step > 0"),
    ("group[0].speed", "unknown key"),
    ("group[1].dts[0]", "does not divide the duration 0.105"),
    ("sweep.dt_min", "must be below dt_max"),
]


def write(tmp_path, text: str, name: str = "trial"):
    path = tmp_path / f"{name}.toml"
    path.write_text(text, encoding="utf-8")
    return path


def test_every_mistake_is_named_with_file_and_field(tmp_path):
    path = write(tmp_path, BAD)
    with pytest.raises(CampaignError) as caught:
        load_campaign(path)
    problems = caught.value.problems
    assert all(problem.file == str(path) for problem in problems)
    for field, words in EXPECTED_PROBLEMS:
        assert any(p.field == field and words in p.message for p in problems), \
            f"{field}: {words!r} not reported; got:\n{caught.value}"
    assert len(problems) == len(EXPECTED_PROBLEMS), str(caught.value)


@pytest.mark.parametrize("text, field, words", [
    ("", "group", "one or more [[group]] tables"),
    ("[[group]]\nscenarios = 'all'\nadapters = 'all'\nmethods = 'best'\ndts = [1e-2]",
     "group[0].methods", "expected a list of method strings"),
    ("[[group]]\nscenarios = 'all'\nmethods = { inhouse = ['best'] }\nadapters = ['inhouse']\n"
     "dts = [1e-2]", "group[0].adapters", "not allowed when methods is a table"),
    ("[[group]]\nscenarios = 'fourbar'\nadapters = 'all'\nmethods = ['best']\ndts = [1e-2]",
     "group[0].scenarios", 'expected "all" or a non-empty list'),
    ("[[group]]\nscenarios = 'all'\nadapters = 'all'\nmethods = ['best']",
     "group[0].dts", "missing required field"),
    ("[[group]]\nscenarios = 'all'\nmethods = { nope = ['best'] }\ndts = [1e-2]",
     "group[0].methods.nope", "unknown adapter 'nope'"),
    ("[[group]]\nscenarios = 'all'\nmethods = { inhouse = ['rk4+direct:proj_tol=abc'] }\n"
     "dts = [1e-2]", "group[0].methods.inhouse[0]", "expects a number"),
    ("[[group]]\nscenarios = ['fourbar']\nexcept = ['fourbar']\nmethods = { inhouse = ['best'] }"
     "\ndts = [1e-2]", "group[0].except", 'allowed only with scenarios = "all"'),
    ("[[group]]\nscenarios = 'all'\nexcept = 'andrews'\nmethods = { inhouse = ['best'] }\n"
     "dts = [1e-3]", "group[0].except", "expected a list of scenario names"),
    ("[[group]]\nscenarios = 'all'\nexcept = ['andrews', 'nowhere']\n"
     "methods = { inhouse = ['best'] }\ndts = [1e-2]", "group[0].except[1]",
     "unknown scenario 'nowhere'"),
])
def test_single_mistakes(tmp_path, text, field, words):
    with pytest.raises(CampaignError) as caught:
        load_campaign(write(tmp_path, text))
    assert any(p.field == field and words in p.message for p in caught.value.problems), \
        str(caught.value)


def test_not_toml_and_unknown_file(tmp_path):
    with pytest.raises(CampaignError, match="not valid TOML"):
        load_campaign(write(tmp_path, "[[group]\n"))
    with pytest.raises(CampaignError, match="no such campaign file"):
        load_campaign("no_such_campaign")


VALID = """
description = "two overlapping groups"
repetitions = 2
timeout_s = 30.0
accuracy = 1e-5
calibration = false

[bounds]
energy = 0.1

[t_end]
"*" = 0.5
slider_crank = 1.0

[[group]]
scenarios = ["slider_crank", "fourbar"]
adapters = ["mujoco", "inhouse"]
methods = ["best"]
dts = [1e-2, 1e-3]
repetitions = 3

[[group]]
scenarios = ["fourbar"]
methods = { inhouse = ["best", "rk4+direct:proj_tol=1e-10"] }
dts = [1e-2]
timeout_s = 5.0
t_end = { fourbar = 0.2 }
"""


def test_valid_file_expands_in_file_order_without_duplicates(tmp_path):
    loaded = load_campaign(write(tmp_path, VALID, "overlap"))
    ids = [case.case_id for case in loaded.cases]
    assert ids == [
        "slider_crank|mujoco|best|0.01|1.0", "slider_crank|mujoco|best|0.001|1.0",
        "slider_crank|inhouse|best|0.01|1.0", "slider_crank|inhouse|best|0.001|1.0",
        "fourbar|mujoco|best|0.01|0.5", "fourbar|mujoco|best|0.001|0.5",
        "fourbar|inhouse|best|0.01|0.5", "fourbar|inhouse|best|0.001|0.5",
        # the second group's t_end (0.2 s) makes new cases, not duplicates of the first group's
        "fourbar|inhouse|best|0.01|0.2", "fourbar|inhouse|rk4+direct:proj_tol=1e-10|0.01|0.2",
    ]
    assert loaded.cases[0] == CaseSpec("slider_crank", "mujoco", "best", 1e-2, 1.0, 3, 30.0)
    assert loaded.cases[-1] == CaseSpec("fourbar", "inhouse", "rk4+direct:proj_tol=1e-10", 1e-2,
                                        0.2, 2, 5.0)
    assert (loaded.name, loaded.accuracy, loaded.calibration, loaded.sweep) == \
        ("overlap", 1e-5, False, None)
    assert loaded.bounds == Bounds(energy=0.1)
    assert loaded.text.startswith("\ndescription")
    assert load_campaign(loaded.path).cases == loaded.cases


def test_a_case_repeated_by_a_later_group_keeps_the_first_groups_settings(tmp_path):
    text = VALID.replace('t_end = { fourbar = 0.2 }', '')
    loaded = load_campaign(write(tmp_path, text))
    first = [c for c in loaded.cases if c.case_id == "fourbar|inhouse|best|0.01|0.5"]
    assert first == [CaseSpec("fourbar", "inhouse", "best", 1e-2, 0.5, 3, 30.0)]
    assert len(loaded.cases) == 9


def test_all_but_the_excepted_scenarios_expand(tmp_path):
    text = ('[[group]]\nscenarios = "all"\nexcept = ["andrews", "bricard"]\n'
            'methods = { inhouse = ["best"] }\ndts = [1e-2]\n')
    cases = load_campaign(write(tmp_path, text)).cases
    assert [c.scenario for c in cases] == [n for n in scenario.scenario_names()
                                           if n not in ("andrews", "bricard")]


def test_sweep_is_read_with_its_durations(tmp_path):
    text = VALID + """
[sweep]
scenarios = ["fourbar", "slider_crank"]
methods = { mujoco = ["best"], inhouse = ["rk4+none"] }
dt_min = 1e-4
dt_max = 1e-2
max_bisections = 5
"""
    sweep = load_campaign(write(tmp_path, text)).sweep
    assert sweep == campaign.SweepSpec(("fourbar", "slider_crank"), ("mujoco", "inhouse"),
                                       {"mujoco": ("best",), "inhouse": ("rk4+none",)},
                                       1e-4, 1e-2, 5, {"fourbar": 0.5, "slider_crank": 1.0},
                                       {"fourbar": 0.01, "slider_crank": 0.01})


def test_case_id_is_readable_and_uses_repr():
    case = CaseSpec("fourbar", "mujoco", "best", 1e-3, 4.0)
    assert case.case_id == "fourbar|mujoco|best|0.001|4.0"


def test_main_output_is_the_first_declared_output():
    assert main_output(scenario.load("fourbar")) == "crank_angle"
    assert main_output(scenario.load("double_fourbar")) == "tip_x"


def test_smoke_covers_every_adapter_and_scenario():
    smoke = load_campaign("smoke")
    assert {c.adapter for c in smoke.cases} == set(adapter_names())
    assert {c.scenario for c in smoke.cases} == set(scenario.scenario_names())
    assert max(c.t_end for c in smoke.cases) <= 0.2
    assert smoke.sweep is not None


def test_nightly_has_every_required_method_over_three_decades():
    nightly = load_campaign("nightly")
    assert len(nightly.cases) >= 500
    pairs = {(c.scenario, c.adapter, c.method) for c in nightly.cases}
    for name in scenario.scenario_names():
        for adapter in adapter_names():
            assert {(name, adapter, "default"), (name, adapter, "best")} <= pairs
        for integrator in ("rk4", "rkn4", "bdf4"):
            for treatment in ("none", "baumgarte", "direct", "partition"):
                assert (name, "inhouse", f"{integrator}+{treatment}") in pairs
        methods = {m for s, a, m in pairs if s == name and a == "inhouse"}
        assert any(m.startswith("dop853") for m in methods)
        assert any(m.startswith("ida") for m in methods)
    steps = [c.dt for c in nightly.cases]
    assert math.log10(max(steps) / min(steps)) >= 3
    assert nightly.sweep is not None


def test_engine_table_is_every_default_and_best():
    table = load_campaign("engine_table")
    assert len(table.cases) == (len(scenario.scenario_names()) * len(adapter_names()) * 2 * 3)
    assert all(c.t_end == scenario.load(c.scenario).duration for c in table.cases)


def test_shipped_campaigns_are_listed():
    assert {"smoke", "nightly", "engine_table"} <= set(campaign.campaign_names())


@pytest.mark.parametrize("name", campaign.campaign_names())
def test_every_shipped_campaign_loads(name):
    """A shipped campaign that does not validate fails its command at once (``mbh bench`` did:
    its fronts gave Andrews' squeezer steps that do not divide its 1 ms grid)."""
    assert load_campaign(name).cases


def test_the_bench_campaign_covers_every_shipped_scene_and_adapter():
    cases = load_campaign("bench").cases
    assert {case.scenario for case in cases} == set(scenario.scenario_names())
    assert {case.adapter for case in cases} == set(adapter_names())
