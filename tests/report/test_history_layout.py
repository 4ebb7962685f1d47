"""The history page's layout: a campaign with a single run says it has no history yet instead of
drawing empty figures, and the changes table fits the page however long its cells (checked in
headless Chromium at a laptop's and a phone's width where Chromium is installed), as do the
trend figures with a long method name."""

from __future__ import annotations

import json
import re
import warnings

import numpy as np
import pytest

from mbh._harness.report.history import find_changes
from mbh._harness.report.history_page import build_history
from tests.report.browser import CHROMIUM, LAPTOP, PHONE, _chromium, _console
from tests.report.history_cases import case, history

#: A method string as long as a campaign may write one.
LONG_METHOD = "ida:rtol=1e-10,atol=1e-12,max_order=5,max_steps=100000,initial_step=1e-6"
SINGLE_RUN = "Only one finished run of campaign"

#: Appended to the page: the changes table's width against its container's, and the console.
PROBE = """
<script>
(function () {
  var table = document.getElementById("changes-table");
  var probe = document.createElement("pre");
  probe.id = "probe";
  probe.textContent = JSON.stringify({table: table.scrollWidth,
                                      room: table.parentElement.clientWidth,
                                      page: document.documentElement.scrollWidth,
                                      window: window.innerWidth});
  document.body.appendChild(probe);
})();
</script>
"""


def _long_history():
    """12 runs of two cases with long names, each with an error step and an engine upgrade."""
    rng = np.random.default_rng(7)
    runs = 12
    cases = [case(rng, runs, LONG_METHOD, scenario="parallelogram_fourbar", adapter="pinocchio"),
             case(rng, runs, "rk4+direct", dt=1.25e-4, scenario="slider_crank_planar")]
    for series in cases:
        series.error[6:] *= 10
        series.version = ["3.1.0-long-build-tag"] * 6 + ["3.2.0-long-build-tag"] * 6
    return history(cases, runs, campaign="a_campaign_with_a_rather_long_name")


def _page(tmp_path, built) -> str:
    page = build_history(root=tmp_path, out=tmp_path / "page", built_at="fixed", history=built,
                         changes=find_changes(built))
    return page.read_text(encoding="utf-8")


def test_a_single_run_says_so_and_draws_no_figure(tmp_path):
    html = _page(tmp_path, history([case(np.random.default_rng(1), 1)], 1))
    assert SINGLE_RUN in html and "No trend is drawn from a single run" in html
    assert '<figure class="fig"' not in html and 'id="filter-scenario"' not in html


def test_two_runs_have_a_history(tmp_path):
    html = _page(tmp_path, history([case(np.random.default_rng(1), 2)], 2))
    assert SINGLE_RUN not in html and html.count('<figure class="fig"') == 1


def test_the_changes_table_has_five_columns_of_fixed_width(tmp_path):
    html = _page(tmp_path, _long_history())
    table = re.search(r'<table class="data" id="changes-table">(.*?)</table>', html, re.DOTALL)
    assert re.findall(r"<th scope=\"col\"[^>]*>([^<]+)</th>", table.group(1)) == [
        "change", "case", "first run", "before → after", "confidence"]
    rows = re.findall(r"<tr>\s*<td class=\"regression\">(.*?)</tr>", table.group(1), re.DOTALL)
    assert len(rows) == 2 * 3  # per case: main-output error, violation, energy
    assert LONG_METHOD in rows[0] and "3.1.0-long-build-tag → 3.2.0-long-build-tag" in rows[0]
    assert "#changes-table { width: 100%; table-layout: fixed; }" in html


def test_a_long_method_name_leaves_the_trend_figures_their_room(tmp_path):
    # its legend entry beside the panels squeezed them to nothing (matplotlib: "constrained_layout
    # not applied because axes sizes collapsed to zero") before it wrapped
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        html = _page(tmp_path, _long_history())
    assert html.count('<figure class="fig"') == 2


@pytest.mark.skipif(CHROMIUM is None, reason="Debian's chromium is not installed")
@pytest.mark.parametrize("size", [LAPTOP, PHONE], ids=["laptop", "phone"])
def test_the_changes_table_fits_the_page_in_a_browser(tmp_path, size):
    probed = tmp_path / "probed.html"
    probed.write_text(_page(tmp_path, _long_history()).replace("</body>", PROBE + "</body>"),
                      encoding="utf-8")
    dom, stderr, _ = _chromium(probed, tmp_path / "dom", size, "--dump-dom")
    assert _console(stderr) == []
    probe = json.loads(re.search(r'<pre id="probe">(.*?)</pre>', dom, re.DOTALL).group(1)
                       .replace("&quot;", '"').replace("&amp;", "&"))
    assert probe["table"] <= probe["room"] and probe["page"] <= probe["window"], probe


@pytest.mark.skipif(CHROMIUM is None, reason="Debian's chromium is not installed")
def test_a_single_run_page_runs_its_script_without_error(tmp_path):
    page = tmp_path / "single.html"
    page.write_text(_page(tmp_path, history([case(np.random.default_rng(1), 1)], 1)),
                    encoding="utf-8")
    _, stderr, _ = _chromium(page, tmp_path / "dom", LAPTOP, "--dump-dom")
    assert _console(stderr) == []
