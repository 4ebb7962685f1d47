"""The warm template (mbh._harness.run.warm) keeps the scenarios it was told to read and their
references, and imports no pandas (that its cases store the rows of fresh interpreters:
tests/run/test_runner.py)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

from mbh._harness.run.executor import WARM_SCENARIOS_ENV


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
