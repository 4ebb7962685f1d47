"""Fixtures of the report tests (test_report.py, test_report_browser.py): a tiny campaign run
through ``mbh run`` and both reports built from it."""

from __future__ import annotations

import json
import re
import subprocess
from pathlib import Path

import pytest

from tests.helpers import MBH, run_mbh, seed_rows

#: The tiny campaign of the fixture run.
REPORT_CAMPAIGN = """\
description = "report test: the four-bar, two engines that work and one that fails at t = 0"
repetitions = 1
timeout_s = 120.0
accuracy = 1e-4
calibration = true

[t_end]
"*" = 0.2

[[group]]
scenarios = ["fourbar"]
adapters = ["inhouse"]
methods = ["rk4+none"]
dts = [1e-2, 1e-3]

[[group]]
scenarios = ["fourbar"]
adapters = ["mujoco", "pinocchio"]
methods = ["default"]
dts = [1e-3]

[sweep]
scenarios = ["fourbar"]
adapters = ["inhouse"]
methods = ["rk4+none"]
dt_min = 5e-3
dt_max = 1e-2
max_bisections = 1
"""


@pytest.fixture(scope="module")
def small_run(tmp_path_factory) -> tuple[Path, str]:
    """(results root, run id) of the tiny campaign run through ``mbh run`` (once per session:
    the browser test's module reuses it)."""
    folder = tmp_path_factory.getbasetemp() / "report_run"
    if (folder / "run_id").is_file():
        return folder / "results", (folder / "run_id").read_text(encoding="utf-8")
    folder.mkdir()
    campaign = folder / "report_test.toml"
    campaign.write_text(REPORT_CAMPAIGN, encoding="utf-8")
    root = folder / "results"
    done = subprocess.run([*MBH, "run", str(campaign), "--root", str(root), "--quiet",
                           "--workers", "2"], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    run_id = re.search(r"^run (\S+):", done.stdout, re.MULTILINE).group(1)
    (folder / "run_id").write_text(run_id, encoding="utf-8")
    return root, run_id


@pytest.fixture(scope="module")
def built(small_run, tmp_path_factory) -> dict[str, Path]:
    """Both reports of the small run, built through ``mbh report`` (seed table stored beside
    the run)."""
    root, run_id = small_run
    (root / run_id / "seed_table.json").write_text(json.dumps(seed_rows()), encoding="utf-8")
    out = tmp_path_factory.mktemp("report_out")
    status, stdout, stderr = run_mbh("report", run_id, "--root", str(root), "--out", str(out),
                                     "--format", "html,pdf")
    assert status == 0, stderr
    assert stdout.split() == [str(out / "report.pdf"), str(out / "report.html")]  # HTML last
    return {"html": out / "report.html", "pdf": out / "report.pdf"}
