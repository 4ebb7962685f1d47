"""Where references are read from and written to: shipped ones from the package, those built here
into the user cache (never into the package); the build's progress bar; ``mbh reference``."""

from __future__ import annotations

import json

import pytest

from mbh._harness.common.locations import shipped
from mbh._harness.common.progress import StageProgress
from mbh._harness.model import scenario
from mbh._harness.references.build import build_reference
from mbh._harness.store.reference_files import cache_dir, reference_paths, search_dirs
from tests.helpers import run_mbh

#: A four-bar of 20 ms: its reference builds in ~2 s (measured).
TINY = ("duration = 4.0", "duration = 0.02")


@pytest.fixture
def user_cache(tmp_path, monkeypatch):
    monkeypatch.delenv("MBH_CACHE_DIR", raising=False)
    monkeypatch.setenv("MBH_CACHE_HOME", str(tmp_path / "cache"))
    return tmp_path / "cache"


@pytest.fixture
def tiny_path(write_scenario):
    return write_scenario("tiny_fourbar", scenario.scenario_path("fourbar").read_text()
                          .replace(*TINY))


def test_shipped_references_are_read_from_the_package_and_new_ones_go_to_the_user_cache(
        user_cache, tiny_path):
    assert search_dirs() == (user_cache / "references", shipped("scenarios") / "references")
    assert reference_paths(scenario.load("fourbar"))[1].parent == shipped("scenarios") / "references"
    status, out, _ = run_mbh("reference", str(tiny_path), "--json", "--quiet")
    assert status == 0
    built = json.loads(out)
    assert built["metadata"].startswith(str(user_cache / "references"))
    assert built["agreement"] <= 1e-9
    assert not list((shipped("scenarios") / "references").glob("tiny_fourbar-*"))
    # Asked again, it is found, not rebuilt: the same files.
    assert json.loads(run_mbh("reference", str(tiny_path), "--json", "--quiet")[1]) == built


def test_mbh_cache_dir_alone_is_searched_when_set(tmp_path, monkeypatch):
    monkeypatch.setenv("MBH_CACHE_DIR", str(tmp_path))
    assert search_dirs() == (tmp_path,) and cache_dir() == tmp_path
    assert reference_paths(scenario.load("fourbar"))[1].parent == tmp_path


def test_a_build_on_a_terminal_shows_its_stages_and_the_time_left(user_cache, tiny_path, capsys):
    build_reference(scenario.load(tiny_path), show_progress=True)
    shown = capsys.readouterr().err
    assert "reference tiny_fourbar" in shown and "left], route A rk4+direct" in shown
    assert "route B rkn4+direct" in shown and "DAE check" in shown
    build_reference(scenario.load(tiny_path), show_progress=False)
    assert capsys.readouterr().err == ""


def test_the_bar_never_runs_past_a_stage_estimate_nor_ends_short():
    bar = StageProgress("test", [0.2, 5.0], enabled=True)
    assert bar.run(0, "first", lambda: 41) + 1 == 42
    assert bar._done == pytest.approx(0.2)
    bar.run(1, "second", lambda: None)   # far shorter than its estimate: jumps to the end
    assert bar._done == pytest.approx(5.2)
    bar.close()


@pytest.mark.filterwarnings("error")
def test_the_bar_ends_at_its_total_when_the_estimates_do_not_round():
    """The total is the estimates' sum itself: rounded to 0.1 s (1.0 for 1.04), the bar ended past
    it and tqdm warned 'clamping frac to range [0, 1]' in a fresh clone's default suite."""
    with StageProgress("test", [1.04], enabled=True) as bar:
        bar.run(0, "only", lambda: None)
        assert bar._done == pytest.approx(bar._bar.total)
