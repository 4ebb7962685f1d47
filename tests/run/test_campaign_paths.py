"""A campaign names its scenarios by shipped name or by a file path relative to itself, so a
user's campaign and scenes live together outside the harness."""

import shutil

import pytest

from mbh._harness.run.spec import CampaignError, load_campaign
from tests.helpers import ROOT


def write_campaign(folder, scenes: str, t_end: str = "") -> None:
    (folder / "campaign.toml").write_text(f'''
calibration = false
{t_end}
[[group]]
scenarios = {scenes}
adapters = ["mujoco"]
methods = ["best"]
dts = [1e-3]
''')


def test_a_scene_file_is_found_relative_to_the_campaign(tmp_path, monkeypatch):
    (tmp_path / "scenes").mkdir()
    shutil.copy(ROOT / "scenarios" / "fourbar.toml", tmp_path / "scenes" / "my_fourbar.toml")
    write_campaign(tmp_path, '["scenes/my_fourbar.toml", "fourbar"]',
                   '[t_end]\n"scenes/my_fourbar.toml" = 0.5\n')
    monkeypatch.chdir(ROOT)  # not the campaign's folder: the path is the file's, not the cwd's
    cases = load_campaign(tmp_path / "campaign.toml").cases
    path = str((tmp_path / "scenes" / "my_fourbar.toml").resolve())
    assert [(case.scenario, case.t_end) for case in cases] == [(path, 0.5), ("fourbar", 4.0)]


def test_a_missing_scene_file_names_the_field_and_the_path(tmp_path):
    write_campaign(tmp_path, '["scenes/absent.toml"]')
    with pytest.raises(CampaignError) as raised:
        load_campaign(tmp_path / "campaign.toml")
    problem, = raised.value.problems
    assert problem.field == "group[0].scenarios[0]"
    assert "absent.toml" in problem.message and "no such scenario file" in problem.message
