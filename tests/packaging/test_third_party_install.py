"""The toy adapter package pip-installed as a user installs a solver's adapter, beside the wheel,
in the fresh environment of tests/packaging/conftest.py (slow).

Checked: ``mbh adapters`` lists the toy with the package that provides it; a user's campaign
naming it next to a built-in engine runs and gives ``ok`` rows; ``mbh report`` builds from that
run; a user's pytest file asserts on the toy through the plugin.
"""

from __future__ import annotations

import json
import re

import pytest

from tests.adapters.conftest import USER_TEST
from tests.packaging.conftest import run

pytestmark = pytest.mark.slow

CAMPAIGN = """\
description = "my solver next to MuJoCo on the four-bar"
calibration = false

[t_end]
"*" = 0.5

[[group]]
scenarios = ["fourbar"]
adapters = ["toy", "mujoco"]
methods = ["best"]
dts = [1e-3]
"""


def test_mbh_adapters_lists_the_installed_package(installed):
    bin_folder, user, env = installed
    rows = json.loads(run([bin_folder / "mbh", "adapters", "--json"], user, env).stdout)
    toy = next(row for row in rows if row["name"] == "toy")
    assert toy == {"name": "toy", "origin": "mbh-toy-adapter", "package_version": "0.1.0",
                   "version": "toy 0.1.0", "methods": 2, "problem": ""}


def test_a_campaign_and_a_report_next_to_a_built_in_engine(installed):
    bin_folder, user, env = installed
    (user / "my_solver.toml").write_text(CAMPAIGN)
    done = run([bin_folder / "mbh", "run", "my_solver.toml", "--quiet"], user, env)
    assert re.search(r": complete, 2 cases \(ok 2\)", done.stdout), done.stdout
    run_id = re.search(r"^run (\S+?):", done.stdout, re.MULTILINE).group(1)
    shown = json.loads(run([bin_folder / "mbh", "show", run_id, "--json"], user, env).stdout)
    assert {row["adapter"]: row["accurate"] for row in shown} == {"toy": True, "mujoco": True}
    run([bin_folder / "mbh", "report", run_id, "--format", "html", "--out", user / "report"],
        user, env)
    html = (user / "report" / "report.html").read_text()
    assert "toy · best" in html and "mujoco · best" in html  # the work-precision series


def test_a_user_test_file_asserts_on_the_toy_through_the_plugin(installed):
    bin_folder, user, env = installed
    suite = user / "toy_suite"  # the session's user folder is shared with tests/packaging
    suite.mkdir()
    (suite / "test_my_solver.py").write_text(USER_TEST)
    done = run([bin_folder / "python", "-m", "pytest", "-q", "-p", "no:cacheprovider"], suite, env)
    assert "1 passed" in done.stdout
