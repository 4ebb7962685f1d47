"""The harness as a user meets it: the wheel installed into a fresh virtual environment outside the
checkout (tests/packaging/conftest.py), used from a folder of the user's (slow: the environment
takes minutes to install, and the in-house kernels compile cold there).

Checked: the wheel carries the scenarios, campaigns and references (``mbh simulate fourbar`` is
``ok`` with a verified reference); a user's own scene builds its reference into the user cache,
never into the installed package; ``mbh run smoke`` and ``mbh report`` work with the default
(user data) results folder; the plugin's documented example suite passes in the user's folder.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from tests.helpers import ROOT, example_suite_files
from tests.packaging.conftest import run

pytestmark = pytest.mark.slow

USER_SCENE = '''
kind = "planar"
plane = "xy"
duration = 1.0
gravity = [0.0, -9.81, 0.0]

[[bodies]]
name = "bar"
mass = 1.0
inertia = [0.0, 0.0833, 0.0833]
position = [0.5, 0.0, 0.0]

[[joints]]
name = "pivot"
type = "revolute"
body1 = "ground"
body2 = "bar"
location = [0.0, 0.0, 0.0]

[initial]
driver = "pivot"
value = 0.0
rate = 0.0

[outputs]
angle = { kind = "joint_angle", joint = "pivot" }
'''


def test_the_installed_package_is_not_the_checkout(installed):
    bin_folder, user, env = installed
    done = run([bin_folder / "python", "-c", "import mbh._harness; print(mbh._harness.__file__)"],
               user, env)
    assert str(ROOT) not in done.stdout and "site-packages" in done.stdout


def test_a_shipped_scene_runs_against_its_shipped_reference(installed):
    bin_folder, user, env = installed
    done = run([bin_folder / "mbh", "simulate", "fourbar", "--adapter", "mujoco", "--method",
                "best", "--dt", "1e-3", "--json"], user, env)
    result = json.loads(done.stdout)
    assert result["status"] == "ok" and result["output_errors"]["crank_angle"] < 1e-3
    assert not (Path(env["XDG_CACHE_HOME"]) / "mbh" / "references").exists()


def test_a_user_scene_builds_its_reference_in_the_user_cache(installed):
    bin_folder, user, env = installed
    (user / "bar_pendulum.toml").write_text(USER_SCENE)
    done = run([bin_folder / "mbh", "simulate", "bar_pendulum.toml", "--adapter", "mujoco",
                "--method", "best", "--dt", "1e-3", "--json"], user, env)
    assert json.loads(done.stdout)["status"] == "ok"
    cached = list((Path(env["XDG_CACHE_HOME"]) / "mbh" / "references").glob("bar_pendulum-*"))
    assert {path.suffix for path in cached} == {".npz", ".json"}
    site = next((bin_folder.parent / "lib").glob("python*/site-packages"))
    assert not list(site.rglob("bar_pendulum*"))


def test_a_campaign_and_its_report_from_the_users_folder(installed):
    bin_folder, user, env = installed
    done = run([bin_folder / "mbh", "run", "smoke"], user, env)
    run_id = re.search(r"^run (\S+?):", done.stdout, re.MULTILINE).group(1)
    folder = Path(re.search(r"^path (.+)$", done.stdout, re.MULTILINE).group(1))
    assert folder.is_relative_to(Path(env["XDG_DATA_HOME"]) / "mbh" / "results")
    run([bin_folder / "mbh", "report", run_id, "--format", "html", "--out", user / "report"],
        user, env)
    assert (user / "report" / "report.html").stat().st_size > 10_000


def test_the_plugin_example_suite_passes_in_the_users_folder(installed):
    bin_folder, user, env = installed
    suite = user / "suite"
    suite.mkdir()
    for name, text in example_suite_files().items():
        (suite / name).write_text(text)
    done = run([bin_folder / "python", "-m", "pytest", "-q", "-p", "no:cacheprovider"], suite, env)
    assert "7 passed" in done.stdout
