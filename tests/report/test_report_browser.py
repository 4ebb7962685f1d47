"""The HTML report in a real headless Chromium (Debian's ``chromium``; ``.ci/run`` installs it).

Chromium is run three ways on a copy of the report with a probe script appended (it writes each
figure's rendered size, the page's scroll width and the order of a table after a click on a
header into the DOM): ``--dump-dom`` at laptop (1366 × 900) and phone (390 × 844) widths, and
``--screenshot`` at both widths (saved under the test's tmp folder).  Console messages come from
``--enable-logging=stderr`` ("CONSOLE" lines); requests from a NetLog (``--log-net-log``), where
a request the page made has an origin as initiator (Chromium's own background requests have
"not an origin").  A control page with a console error and two external resources checks that
both detectors see what they must.
"""

from __future__ import annotations

import json
import re
from html import escape
from pathlib import Path

import pytest

from tests.report.browser import (LAPTOP, PHONE, _chromium, _console, _page_requests,
                                  needs_chromium)

pytestmark = needs_chromium

PROBE = """
<script>
(function () {
  var figures = document.querySelectorAll("figure.fig");
  var sizes = Array.prototype.map.call(figures, function (fig) {
    var box = fig.querySelector("svg").getBoundingClientRect();
    return [box.width, box.height];
  });
  var table = document.getElementById("cases-table");
  var header = table.tHead.rows[0].cells[9];  // wall time (s)
  header.click();
  var order = Array.prototype.map.call(table.tBodies[0].rows, function (row) {
    return row.cells[9].getAttribute("data-sort");
  });
  var probe = document.createElement("pre");
  probe.id = "probe";
  probe.textContent = JSON.stringify({
    figures: figures.length, sizes: sizes, scrollWidth: document.documentElement.scrollWidth,
    innerWidth: window.innerWidth, sorted: order, sort: header.getAttribute("aria-sort")});
  window.parent.document.body.appendChild(probe);  // the top document when framed
})();
</script>
"""


def _probed_page(html: str, folder: Path, size: tuple[int, int]) -> tuple[Path, tuple[int, int]]:
    """The report with :data:`PROBE` appended, and the window size to open it with.

    Headless Chromium lays a window out at least 500 px wide, so a narrower (phone) width is
    given to the report as an iframe of that size (``srcdoc``: same origin as its parent) in a
    500 px window.
    """
    folder.mkdir(parents=True, exist_ok=True)
    probed = html.replace("</body>", PROBE + "</body>")
    page = folder / "page.html"
    if size[0] >= 500:
        page.write_text(probed, encoding="utf-8")
        return page, size
    page.write_text(f'<!DOCTYPE html><html><body style="margin:0"><iframe '
                    f'style="border:0;display:block" width="{size[0]}" height="{size[1]}" '
                    f'srcdoc="{escape(probed, quote=True)}"></iframe></body></html>',
                    encoding="utf-8")
    return page, (500, size[1])


def test_detectors_see_a_console_error_and_an_external_request(tmp_path):
    page = tmp_path / "control.html"
    page.write_text('<!DOCTYPE html><html><body><img src="https://example.com/x.png">'
                    '<script>console.error("control-error");</script></body></html>',
                    encoding="utf-8")
    _, stderr, netlog = _chromium(page, tmp_path / "control", LAPTOP, "--dump-dom")
    assert any("control-error" in line for line in _console(stderr))
    assert _page_requests(netlog) == ["https://example.com/x.png"]


@pytest.mark.parametrize("name,size", [("laptop", LAPTOP), ("phone", PHONE)])
def test_report_renders_offline_without_errors(built, tmp_path, name, size):
    html = built["html"].read_text(encoding="utf-8")
    page, window = _probed_page(html, tmp_path / "probed", size)
    dom, stderr, netlog = _chromium(page, tmp_path / "dom", window, "--dump-dom")
    assert _console(stderr) == []
    assert _page_requests(netlog) == []
    probe = json.loads(re.search(r'<pre id="probe">(.*?)</pre>', dom, re.DOTALL).group(1)
                       .replace("&quot;", '"').replace("&amp;", "&"))
    sizes = probe["sizes"]
    assert probe["figures"] == html.count('<figure class="fig') == len(sizes) > 0
    assert all(width > 0 and height > 0 for width, height in sizes), sizes
    # Readable at this width: nothing wider than the window (wide tables scroll in their box).
    assert probe["scrollWidth"] <= probe["innerWidth"] == size[0]
    # A click on the wall-time header sorts the table by value.
    times = [float(v) for v in probe["sorted"] if v]
    assert probe["sort"] == "ascending" and times == sorted(times) and len(times) > 1
    shot = tmp_path / f"report-{name}.png"
    _chromium(page, tmp_path / "shot", window, f"--screenshot={shot}")
    assert shot.stat().st_size > 10_000
