"""A user's script that starts a campaign at its top level, with no ``if __name__ ==
"__main__":`` guard, runs its cases: the warm workers do not re-run the script that started them
(multiprocessing's child preparation would, and refuse to start a process from there, leaving
every case ``crashed``)."""

import subprocess
import sys

CAMPAIGN = """
calibration = false

[t_end]
"*" = 0.1

[[group]]
scenarios = ["fourbar"]
methods = { inhouse = ["rk4+direct"], mujoco = ["best"] }
dts = [1e-2]
"""

SCRIPT = """
import mbh

store = mbh.run_campaign("campaign.toml", workers=1, root="results")
print(" ".join(sorted(store.cases()["status"])))
"""


def test_a_script_without_a_main_guard_runs_its_campaign(tmp_path):
    (tmp_path / "campaign.toml").write_text(CAMPAIGN)
    (tmp_path / "script.py").write_text(SCRIPT)
    run = subprocess.run([sys.executable, "script.py"], cwd=tmp_path, capture_output=True,
                         text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    assert run.stdout.split() == ["ok", "ok"], run.stderr
