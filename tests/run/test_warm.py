"""The warm template (mbh._harness.run.warm) keeps the scenarios it was told to read and their
references, computes the failure label's conditioning of the scenes it was told, runs the
methods it was told once, and imports no pandas (that its cases store the rows of fresh interpreters:
tests/run/test_runner.py)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

from mbh._harness.run.campaign import conditioned_ahead, first_runs
from mbh._harness.run.executor import (WARM_CONDITIONED_ENV, WARM_METHODS_ENV, WARM_SAY_ENV,
                                      WARM_SCENARIOS_ENV)
from mbh._harness.run.spec import load_campaign


def test_the_template_keeps_the_scenarios_it_was_told_to_read_and_their_references():
    script = """
import sys
from mbh._harness.model import scenario
from mbh._harness.references.build import reference_trajectory
import mbh._harness.run.warm
import mbh._harness.run.calibration, mbh._harness.run.row  # what a case unpickles: its work and spec

told, other = scenario.load("fourbar"), scenario.load("slider_crank")
print(told is scenario.load("fourbar"), other is scenario.load("slider_crank"),
      reference_trajectory(told) is reference_trajectory(told),
      reference_trajectory(told).position.flags.writeable, mbh._harness.run.warm.MISSED,
      "pandas" in sys.modules)
"""
    env = os.environ | {WARM_SCENARIOS_ENV: json.dumps(["fourbar"])}
    done = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True,
                          text=True, check=True)
    # A case never needs pandas (the store is the campaign's process's): importing it added
    # 0.37 s to the template's start, and to every case whose work's module imported it.
    assert done.stdout.split() == ["True", "False", "True", "False", "[]", "False"], done.stderr


def test_the_template_runs_each_method_it_was_told_and_reports_one_that_fails():
    """The campaign's methods run once in the template, so their compiled loops are loaded there
    (the implicit multistep loop of bdf4 here, which the template's own warm-up cases do not
    load), and a method that cannot run is reported, not raised."""
    script = """
import mbh._harness.run.warm as warm
from mbh._adapters.inhouse.stepping import compiled_multistep
print(len(compiled_multistep.run_samples.overloads), len(warm.MISSED))
print(warm.MISSED)
"""
    told = [["fourbar", "inhouse", "bdf4+direct", 1e-3], ["fourbar", "inhouse", "rk4+nosuch", 1e-3]]
    lines = {}
    for methods in ([], told):
        env = os.environ | {WARM_METHODS_ENV: json.dumps(methods)}
        done = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True,
                              text=True, check=True)
        lines[len(methods)] = done.stdout.splitlines()
    assert lines[0][0] == "0 0"
    assert lines[2][0] == "1 1"
    assert "fourbar/inhouse/rk4+nosuch" in lines[2][1]


def test_first_runs_name_each_method_of_a_campaign_once_with_its_first_case():
    campaign = load_campaign("nightly")
    runs = first_runs(campaign)
    pairs = [(adapter, method) for _, adapter, method, _ in runs]
    assert len(pairs) == len(set(pairs))
    assert set(pairs) == ({(spec.adapter, spec.method) for spec in campaign.cases}
                          | {(adapter, method) for adapter, methods in campaign.sweep.methods.items()
                             for method in methods})
    first = campaign.cases[0]
    assert runs[0] == (first.scenario, first.adapter, first.method, first.dt)


def test_the_template_says_its_waits_when_its_starting_process_does():
    """On a machine where the kernels are not compiled yet the template compiles them before any
    case can start: it says so on stderr as the starting process would (not under --quiet)."""
    script = """
import mbh._harness.run.warm
from mbh._harness.common import waits
print(waits.shown_on_stderr())
"""
    said = {}
    for value in ("1", ""):
        env = os.environ | {WARM_SAY_ENV: value}
        done = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True,
                              text=True, check=True)
        said[value] = done.stdout.strip()
    assert said == {"1": "True", "": "False"}


def test_the_template_computes_the_conditioning_of_the_scenes_it_was_told():
    """The failure label's conditioning is computed ahead for the scenes with many cases in the
    campaign (none of the smoke's, every one of the nightly's) and only for those."""
    assert conditioned_ahead(load_campaign("smoke")) == set()
    nightly = load_campaign("nightly")
    assert conditioned_ahead(nightly) == {spec.scenario for spec in nightly.cases}
    # After the template's start, a case asks for the conditioning of the reference it loads
    # (mbh._harness.run.row): the SVDs run again only for the scene the template was not told.
    script = """
import mbh._harness.run.warm
from mbh._harness.measure import failure_label
from mbh._harness.model import scenario
from mbh._harness.references.build import reference_trajectory

computed, compute = [], failure_label.conditioning
def counted(mech, reference):
    computed.append(mech.name)
    return compute(mech, reference)
failure_label.conditioning = counted
for name in ("fourbar", "slider_crank"):
    mech = scenario.load(name)
    failure_label.reference_conditioning(mech, reference_trajectory(mech))
print(computed)
"""
    env = os.environ | {WARM_SCENARIOS_ENV: json.dumps(["fourbar", "slider_crank"]),
                        WARM_CONDITIONED_ENV: json.dumps(["fourbar"])}
    done = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True,
                          text=True, check=True)
    assert done.stdout.strip() == repr(["slider_crank"]), done.stderr
