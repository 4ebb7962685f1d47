"""A solver without packaging: an adapter passed as a class or an instance wherever a registered
name goes (``mbh.run_case``, ``mbh.run_campaign``) is judged and stored exactly as a registered
one.  The adapter is the toy of the adapter guide, written against ``mbh.adapters`` alone.
"""

from __future__ import annotations

import dataclasses
import json
import re

import pandas as pd
import pytest

import mbh
from mbh._adapters import resolve_adapter
from mbh._harness.run.campaign import run_campaign
from mbh.adapters import AdapterLoadError

#: The columns that differ between two runs of one case: its wall times.
TIMES = ["wall_time_s", "wall_time_per_sim_s", "wall_time_per_step_s", "wall_times_s"]


def toy_subclass(class_name: str, **attributes) -> type:
    """A subclass ``class_name`` of the toy adapter, in this module, with ``attributes``."""
    from mbh_toy_adapter import ToyAdapter

    return type(class_name, (ToyAdapter,), {"__module__": __name__, **attributes})


def case_row(adapter) -> pd.DataFrame:
    """The stored-run row of the toy's case on the four-bar, wall times left out."""
    result = mbh.run_case("fourbar", adapter, "best", dt=1e-3, t_end=0.2)
    return result.to_frame().drop(columns=TIMES)


def test_the_registered_toy_by_name_class_or_instance_gives_one_row(toy):
    from mbh_toy_adapter import ToyAdapter

    by_name = case_row("toy")
    assert by_name.loc[0, "status"] == "ok"
    assert json.loads(by_name.loc[0, "packages"])["adapter_package"] == "mbh-toy-adapter 0.1.0"
    pd.testing.assert_frame_equal(case_row(ToyAdapter), by_name)
    pd.testing.assert_frame_equal(case_row(ToyAdapter()), by_name)


def test_an_unregistered_class_runs_under_its_own_name_without_a_package(toy_module):
    from mbh_toy_adapter import ToyAdapter

    row = case_row(ToyAdapter)
    assert (row.loc[0, "adapter"], row.loc[0, "status"], row.loc[0, "case_id"]) == (
        "toy", "ok", "fourbar|toy|best|0.001|0.2")
    assert row.loc[0, "main_output_error"] < 1e-8  # measured 1.4e-11 rad
    assert "adapter_package" not in json.loads(row.loc[0, "packages"])
    assert case_row(toy_subclass("MyToy", name="mine")).loc[0, "case_id"] == "fourbar|mine|best|0.001|0.2"


def test_what_cannot_stand_for_an_adapter_is_an_input_error_that_says_why(toy_module):
    from mbh_toy_adapter import ToyAdapter

    refused = {
        toy_subclass("Nameless", name=""):
            "adapter: adapter class tests.adapters.test_given_adapters:Nameless has no name: "
            "set its class attribute `name`",
        toy_subclass("Impostor", name="mujoco"):
            "adapter: adapter class tests.adapters.test_given_adapters:Impostor is named "
            "'mujoco', the name of the registered adapter 'mujoco' (built-in); give the class "
            "another name",
        object: "adapter: expected an adapter name, an Adapter subclass or an instance of one",
    }
    for adapter, message in refused.items():
        with pytest.raises(mbh.CaseInputError, match=re.escape(message)):
            mbh.run_case("fourbar", adapter, "best", dt=1e-3, t_end=0.1)
    with pytest.raises(mbh.CaseInputError, match="method: unknown toy method 'rk9'"):
        mbh.run_case("fourbar", ToyAdapter, "rk9", dt=1e-3, t_end=0.1)


def test_a_class_that_fails_to_construct_is_named(toy_module):
    def broken_init(self):
        raise OSError("no licence file")

    broken = toy_subclass("Unlicensed", __init__=broken_init)
    with pytest.raises(AdapterLoadError, match=re.escape(
            "adapter class tests.adapters.test_given_adapters:Unlicensed cannot be constructed: "
            "OSError: no licence file")):
        mbh.run_case("fourbar", broken, "best", dt=1e-3, t_end=0.1)


CAMPAIGN = """\
description = "your solver beside a built-in engine"
calibration = false

[t_end]
"*" = 0.2

[[group]]
scenarios = ["fourbar"]
adapters = ADAPTERS
methods = ["best"]
dts = [1e-3]
"""


#: The note of a campaign whose ``adapters = "all"`` took in the registered toy adapter.
ALL_TOOK_THE_TOY = ('adapters = "all" took in the third-party adapter \'toy\' from package '
                    'mbh-toy-adapter 0.1.0; name the adapters in the file to leave it out')


def campaign_file(folder, adapters: str):
    path = folder / "mine.toml"
    path.write_text(CAMPAIGN.replace("ADAPTERS", adapters))
    return path


def test_a_campaign_runs_a_given_class_in_its_workers_as_run_case_does(toy_module, tmp_path):
    from mbh_toy_adapter import ToyAdapter

    path = campaign_file(tmp_path, '["toy", "mujoco"]')
    with pytest.raises(mbh.CampaignError, match=r"group\[0\]\.adapters\[0\]: unknown adapter 'toy'"):
        mbh.load_campaign(path)
    run = mbh.run_campaign(path, adapters=[ToyAdapter()], workers=1, root=tmp_path / "results")
    stored = run.cases().set_index("adapter")
    assert list(stored["status"]) == ["ok", "ok"]
    in_process = case_row(ToyAdapter).set_index("adapter")
    columns = [column for column in in_process.columns if column in stored.columns]
    pd.testing.assert_frame_equal(stored.loc[["toy"], columns], in_process[columns],
                                  check_dtype=False)


def test_an_adapter_that_cannot_reach_the_workers_is_refused_with_what_it_needs(toy_module,
                                                                                 tmp_path):
    from mbh_toy_adapter import ToyAdapter

    class Local(ToyAdapter):
        name = "local"

    unpicklable = ToyAdapter()
    unpicklable.hook = lambda: None
    refused = {
        Local: "class test_an_adapter_that_cannot_reach_the_workers_is_refused_with_what_it_"
               "needs.<locals>.Local is defined inside a function",
        toy_subclass("Scripted", __module__="__main__", name="scripted"):
            "class Scripted is defined in the script being run (__main__)",
        toy_subclass("Elsewhere", __module__="not_on_the_path", name="elsewhere"):
            "module not_on_the_path of class Elsewhere cannot be imported by name from sys.path",
        toy_subclass("Unlisted", name="unlisted"): "it does not pickle (PicklingError",
        unpicklable: "it does not pickle (AttributeError: Can't pickle local object",
    }
    for adapter, problem in refused.items():
        name = resolve_adapter(adapter).name
        path = campaign_file(tmp_path, f'["{name}"]')
        with pytest.raises(mbh.MbhError, match=re.escape(
                f"adapter {name!r} cannot reach the campaign's worker processes: {problem}")) \
                as refusal:
            mbh.run_campaign(path, adapters=[adapter], root=tmp_path / "results")
        assert "define it at the top level of a module on sys.path" in str(refusal.value)
    assert not (tmp_path / "results").exists()  # refused before anything ran


def test_all_takes_in_given_and_installed_adapters_but_shipped_campaigns_do_not(toy,
                                                                                 tmp_path):
    mine = toy_subclass("MyToy", name="mine")
    taken = mbh.load_campaign(campaign_file(tmp_path, '"all"'), adapters=[mine])
    assert [case.adapter for case in taken.cases] == [
        "inhouse", "mujoco", "pybullet", "pinocchio", "exudyn", "toy", "mine"]
    assert taken.notes == (ALL_TOOK_THE_TOY,)
    smoke = mbh.load_campaign("smoke")
    assert {case.adapter for case in smoke.cases} == {
        "inhouse", "mujoco", "pybullet", "pinocchio", "exudyn"}
    assert smoke.notes == ()


def test_a_run_that_all_took_a_third_party_adapter_into_says_so(toy, tmp_path, capsys):
    campaign = mbh.load_campaign(campaign_file(tmp_path, '"all"'))
    toy_cases = tuple(case for case in campaign.cases if case.adapter == "toy")
    store = run_campaign(dataclasses.replace(campaign, cases=toy_cases), workers=1,
                         root=tmp_path / "results", quiet=False)
    assert f"mbh: {ALL_TOOK_THE_TOY}" in capsys.readouterr().err.splitlines()
    assert mbh.list_runs(tmp_path / "results")[0]["notes"] == [ALL_TOOK_THE_TOY]
    assert list(store.cases()["status"]) == ["ok"]
