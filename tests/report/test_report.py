"""``mbh report``: HTML and PDF built from a stored run (a tiny campaign run by ``mbh run``).

The run (module fixture ``small_run``): the four-bar for 0.2 s, in-house rk4+none at two steps,
MuJoCo's default, and Pinocchio's default at 1e-3 s, which fails at t = 0 (a non-finite
acceleration; measured in the smoke run of 2026-11-23), plus a one-method stability sweep.  It
takes about 20 s on the 2-core development machine (every case in its own process).
"""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from mbh._harness.report import build
from mbh._harness.store.manifest import latest_run
from mbh._harness.store.runs import RunStore
from tests.helpers import MBH, run_mbh, seed_rows

#: Markup in a scenario name and in a method parameter (the escaping test's run).
EVIL_SCENARIO = "<b>evil</b>&scene"
EVIL_METHOD = "rk4+none:tol=<script>alert(1)</script>"


@pytest.fixture(scope="module")
def run_store(small_run) -> RunStore:
    root, run_id = small_run
    return RunStore.open(run_id, root)


class _Campaign:
    """The campaign attributes :meth:`RunStore.create` reads (no cases: rows are added by hand)."""

    def __init__(self, name: str):
        self.name, self.path, self.cases, self.sweep = name, Path(f"{name}.toml"), (), None
        self.text = f'description = "{name}: rows copied from the report test run"\naccuracy = 1e-4\n'


def _copy_run(source: RunStore, root: Path, name: str, edit) -> RunStore:
    """A new run of campaign ``name`` holding ``source``'s rows, each passed through
    ``edit(row) -> row`` (trajectories copied), with ``source``'s calibration."""
    store = RunStore.create(_Campaign(name), root)
    for row in source.cases().to_dict("records"):
        row = {k: (None if v is pd.NA else v) for k, v in row.items()
               if k not in ("run_id", "trajectory_file")}
        trajectory = source.trajectory(row["case_id"])
        store.add(edit(row), trajectory)
    store.set_calibration(source.calibration_s)
    store.finish("complete")
    return store


#: Sections of the report in reading order (HTML ids; the PDF has the same headings).
SECTIONS = {"summary": "Summary", "work-precision": "Work–precision diagrams",
            "stability": "Stability maps", "histories": "Time histories",
            "model-size-section": "Model size and cost", "mechanisms": "Mechanisms",
            "seed": "The seed's comparison", "environment": "Environment and reproduction",
            "all-cases": "All cases"}


def _page_texts(pdf: Path) -> list[str]:
    import pypdfium2

    document = pypdfium2.PdfDocument(str(pdf))
    return [document[i].get_textpage().get_text_range() for i in range(len(document))]


def test_html_holds_every_section_in_order_and_every_figure(built, run_store):
    html = built["html"].read_text(encoding="utf-8")
    positions = [html.index(f'<section id="{key}">') for key in SECTIONS]
    assert positions == sorted(positions)
    # One scenario: 3 work-precision diagrams, 1 stability map, the time history of the fastest
    # case within 1e-4 (the failing Pinocchio case has one sample: a note instead), a mechanism
    # picture and its animation.
    assert html.count('<figure class="fig') == 7
    assert "pinocchio default dt=0.001 ended failed at t = 0 s with one stored sample" in html
    # Self-contained: no external reference in any src/href, no <link>, no remote script.
    assert not re.search(r'(src|href)\s*=\s*["\']?\s*(https?:)?//', html)
    assert "<link" not in html
    assert run_store.run_id in html


def test_summary_picks_the_fastest_ok_case_per_level(run_store):
    from mbh._harness.report.summary import ACCURACY_LEVELS, fastest_table

    cases = run_store.cases()
    table = fastest_table(cases, "fourbar", run_store.calibration_s)
    rows = cases.to_dict("records")
    for level, row in zip(ACCURACY_LEVELS, table.rows):
        candidates = [r for r in rows if r["status"] == "ok" and r["main_output_error"] <= level]
        assert row[-1] == len(candidates)
        if candidates:
            best = min(candidates, key=lambda r: r["wall_time_s"])
            assert (row[1], row[2], row[3]) == (best["adapter"], best["method"], best["dt"])
            assert row[6] == pytest.approx(best["wall_time_s"] / run_store.calibration_s)
        else:
            assert row[1] == "none reaches it"
    # The failing case is counted, with its reason, and never picked.
    counts = {r[1]: r for r in build.summary.status_counts_table(cases).rows}
    assert counts["pinocchio"][-1] == 1 and "failed" in build.summary.status_counts_table(cases).columns


def test_pdf_pages_render_with_content_in_html_order(built):
    import pypdfium2

    document = pypdfium2.PdfDocument(str(built["pdf"]))
    texts = _page_texts(built["pdf"])
    # Five forced page breaks (figures, seed, environment, all cases) give at least 5 pages.
    assert len(document) >= 5
    pages = [next(i for i, text in enumerate(texts) if heading in text)
             for heading in SECTIONS.values()]
    assert pages == sorted(pages)
    assert_no_blank_page(document)


def assert_no_blank_page(document) -> None:
    """Every page of a pypdfium2 document carries more than the footer line: ink in the page
    body, above the footer band (the bottom 8 %)."""
    for index in range(len(document)):
        pixels = document[index].render(scale=0.5, grayscale=True).to_numpy()
        body = pixels[:int(0.92 * pixels.shape[0])]
        ink = float((body < 250).mean())
        # The body of a footer-only page has no ink; the least-inked page measured, two lines
        # of the smoke report's campaign file carried over, has 8.9e-4: 1e-4 separates them.
        assert ink > 1e-4, f"page {index + 1} is blank (ink fraction {ink:.2g} above the footer)"


@pytest.mark.slow
def test_both_reports_build_from_the_shipped_smoke_campaign(tmp_path):
    import pypdfium2

    root = tmp_path / "results"
    done = subprocess.run([*MBH, "run", "smoke", "--root", str(root), "--quiet"],
                          capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr
    run_id = re.search(r"^run (\S+):", done.stdout, re.MULTILINE).group(1)
    status, stdout, stderr = run_mbh("report", run_id, "--root", str(root), "--out",
                                     str(tmp_path / "out"), "--format", "html,pdf")
    assert status == 0, stderr
    html = (tmp_path / "out" / "report.html").read_text(encoding="utf-8")
    for name in ("fourbar", "fourbar_spatial", "slider_crank", "slider_crank_planar",
                 "double_fourbar"):
        assert f"{name}: largest error of the main output" in html
    document = pypdfium2.PdfDocument(str(tmp_path / "out" / "report.pdf"))
    assert len(document) >= 5
    assert_no_blank_page(document)


def test_two_builds_differ_only_in_the_timestamp(built, small_run, tmp_path):
    root, run_id = small_run
    first = built["html"].read_text(encoding="utf-8")
    stamp = re.search(r"data-build-timestamp>Built (\S+)<", first).group(1)
    # The same timestamp: both files byte for byte the same.
    same = build.build_report(run_id, out=tmp_path / "same", root=root, built_at=stamp)
    assert same["html"].read_text(encoding="utf-8") == first
    assert same["pdf"].read_bytes() == built["pdf"].read_bytes()
    # Another timestamp: the HTML differs in the timestamp line only.
    other = build.build_report(run_id, out=tmp_path / "other", root=root, formats=("html",),
                               built_at="2001-02-03T04:05:06+00:00")
    second = other["html"].read_text(encoding="utf-8")
    differing = [(a, b) for a, b in zip(first.splitlines(), second.splitlines()) if a != b]
    assert len(first.splitlines()) == len(second.splitlines())
    assert differing == [(f'  <p class="built" data-build-timestamp>Built {stamp}</p>',
                          '  <p class="built" data-build-timestamp>Built 2001-02-03T04:05:06+00:00</p>')]


def test_markup_in_names_and_parameters_is_escaped(run_store, small_run, tmp_path):
    root, _ = small_run

    def evil(row):
        return {**row, "scenario": EVIL_SCENARIO, "method": EVIL_METHOD,
                "case_id": row["case_id"].replace("fourbar", EVIL_SCENARIO).replace(
                    row["method"], EVIL_METHOD)}

    store = _copy_run(run_store, tmp_path / "results", "escape", evil)
    written = build.build_report(store.run_id, out=tmp_path / "out", root=tmp_path / "results")
    html = written["html"].read_text(encoding="utf-8")
    assert "<b>evil" not in html and "<script>alert" not in html
    assert "&lt;b&gt;evil&lt;/b&gt;&amp;scene" in html
    assert "rk4+none:tol=&lt;script&gt;alert(1)&lt;/script&gt;" in html
    # The scenario does not load, so nothing is drawn from its states, and the report says so.
    assert "the scenario does not load now" in html
    # In the PDF the markup is text, not formatting.
    text = "".join(_page_texts(written["pdf"]))
    assert EVIL_SCENARIO in text and "alert(1)" in text


def test_changes_against_a_previous_run(run_store, small_run, tmp_path):
    root, run_id = small_run
    failing = run_store.cases().query("status != 'ok'")["case_id"].iloc[0]
    timed = run_store.cases().query("adapter == 'inhouse' and dt == 0.001")["case_id"].iloc[0]

    def before(row):
        # The previous run: the failing case was ok, the in-house 1e-3 case 10 × faster.
        if row["case_id"] == failing:
            return {**row, "status": "ok", "reason": "", "failure_time": float("nan")}
        if row["case_id"] == timed:
            return {**row, "wall_time_s": row["wall_time_s"] / 10}
        return row

    previous = _copy_run(run_store, tmp_path / "results", "report_test", before)
    # The copy started later, so the small run is the previous run of the copy, not vice versa.
    campaign = previous.manifest["campaign"]
    assert latest_run(campaign, tmp_path / "results", before=previous.run_id) is None
    shutil.copytree(root / run_id, tmp_path / "results" / run_id)
    assert latest_run(campaign, tmp_path / "results", before=previous.run_id) == run_id
    report = build.collect(run_id, against=previous.run_id, root=tmp_path / "results")
    changes = {row[0]: row for row in report.changes.rows}
    assert changes["newly failing"][3] == "default" and changes["newly failing"][6] == "failed"
    assert changes["slower"][8] == pytest.approx(10.0, rel=1e-12)


def test_seed_comparison_sets_ours_beside_theirs(run_store, built):
    from mbh._harness.report import seed_compare

    published = seed_compare.load_published()
    table = seed_compare.comparison_table(published, seed_rows())
    rows = {(r[0], r[1], r[2], r[3]): r for r in table.rows}
    row = rows[("max constraint error (m ours)", "fourbar_spatial", "rk4", "none")]
    assert row[4] == 0.009848036 and row[5] == 2e-3 and row[6] == pytest.approx(2e-3 / 0.009848036)
    # Tables 9 and 10 publish no Gear with direct correction: 2 quantities × 2 mechanisms × 3
    # stabilisations × 3 integrators − 4 missing + table 11's 18 = 50 rows.
    assert len(table.rows) == 50
    energy = rows[("max energy-balance error (J ours)", "slider_crank", "rk4", "none")]
    assert np.isnan(energy[5]) and np.isnan(energy[6])
    html = built["html"].read_text(encoding="utf-8")
    assert "Rouvinen, A. (2003)" in html and "missing" not in html.split('id="seed"')[1][:2000]


def test_missing_or_bad_seed_table_is_said(run_store, tmp_path):
    from mbh._harness.report import seed_compare

    assert seed_compare.load_ours(tmp_path) is None
    (tmp_path / "seed_table.json").write_text('{"not": "rows"}', encoding="utf-8")
    with pytest.raises(seed_compare.SeedTableError, match="seed_table.json: expected the list"):
        seed_compare.load_ours(tmp_path)


def test_cli_errors_exit_2(small_run, tmp_path):
    root, run_id = small_run
    status, _, stderr = run_mbh("report", "no-such-run", "--root", str(root))
    assert status == 2 and "no run 'no-such-run'" in stderr and run_id in stderr
    status, _, stderr = run_mbh("report", run_id, "--root", str(root), "--format", "html,docx",
                                "--out", str(tmp_path))
    assert status == 2 and "unknown: docx" in stderr and not any(tmp_path.iterdir())
