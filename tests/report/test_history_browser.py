"""The history page in a real headless Chromium (as tests/report/test_report_browser.py does for
the run report): no console message, no request, every figure drawn, and the filters hide the
figures they must."""

from __future__ import annotations

import json
import re

from mbh._harness.report.history import find_changes
from mbh._harness.report.history_page import build_history
from tests.report.history_cases import case, history
from tests.report.browser import LAPTOP, _chromium, _console, _page_requests, needs_chromium

pytestmark = needs_chromium

#: Appended to the page: choose scenario "slider_crank", then "with changes only", and record
#: how many figures each choice leaves shown.
PROBE = """
<script>
(function () {
  function shown() {
    return Array.prototype.filter.call(document.querySelectorAll("#trend-figures figure"),
      function (figure) { return !figure.hidden; }).length;
  }
  var figures = document.querySelectorAll("figure.fig");
  var sizes = Array.prototype.map.call(figures, function (fig) {
    var box = fig.querySelector("svg").getBoundingClientRect();
    return [box.width, box.height];
  });
  var all = shown();
  var scenario = document.getElementById("filter-scenario");
  scenario.value = "slider_crank";
  scenario.dispatchEvent(new Event("change"));
  var oneScene = shown();
  scenario.value = "";
  scenario.dispatchEvent(new Event("change"));
  var changed = document.getElementById("filter-changed");
  changed.checked = true;
  changed.dispatchEvent(new Event("change"));
  var probe = document.createElement("pre");
  probe.id = "probe";
  probe.textContent = JSON.stringify({all: all, oneScene: oneScene, changed: shown(),
    sizes: sizes, count: document.getElementById("trend-count").textContent});
  document.body.appendChild(probe);
})();
</script>
"""


def test_history_page_renders_offline_and_filters(tmp_path):
    import numpy as np

    rng = np.random.default_rng(5)
    runs = 12
    stepped = case(rng, runs, "rk4+direct")
    stepped.error[6:] *= 10
    cases = [stepped, case(rng, runs, "best", adapter="mujoco"),
             case(rng, runs, "rk4+direct", scenario="slider_crank")]
    built = history(cases, runs)
    page = build_history(root=tmp_path, out=tmp_path / "page", built_at="fixed", history=built,
                         changes=find_changes(built))
    probed = tmp_path / "probed.html"
    probed.write_text(page.read_text(encoding="utf-8").replace("</body>", PROBE + "</body>"),
                      encoding="utf-8")
    dom, stderr, netlog = _chromium(probed, tmp_path / "dom", LAPTOP, "--dump-dom")
    assert _console(stderr) == []
    assert _page_requests(netlog) == []
    probe = json.loads(re.search(r'<pre id="probe">(.*?)</pre>', dom, re.DOTALL).group(1)
                       .replace("&quot;", '"').replace("&amp;", "&"))
    # Three figures (fourbar · inhouse · rk4, fourbar · mujoco · default & best,
    # slider_crank · inhouse · rk4); one on slider_crank; one with a change.
    assert (probe["all"], probe["oneScene"], probe["changed"]) == (3, 1, 1)
    assert probe["count"] == "1 of 3 figures"
    assert len(probe["sizes"]) == 3 and all(w > 0 and h > 0 for w, h in probe["sizes"])
