"""A solver without packaging: an adapter passed as a class or an instance wherever a registered
name goes (``mbh.run_case``, ``mbh.run_campaign``) is judged and stored exactly as a registered
one.  The adapter is the toy of the adapter guide, written against ``mbh.adapters`` alone.
"""

from __future__ import annotations

import json
import re

import pandas as pd
import pytest

import mbh
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
