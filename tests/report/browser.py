"""Headless Chromium for the HTML pages' tests (the run report, the history page): where it is,
how it is started, and what it printed and requested."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import pytest

CHROMIUM = shutil.which("chromium") or ("/usr/bin/chromium" if Path("/usr/bin/chromium").exists()
                                        else None)

#: Marks a test module that runs Chromium: skipped, saying why, where it is not installed (the
#: README's set-up installs Python packages only; ``.ci/run`` installs Chromium where it runs as root).
needs_chromium = pytest.mark.skipif(
    CHROMIUM is None, reason="Debian's chromium is not installed (apt-get install -y chromium; "
                             ".ci/run installs it where it runs as root)")

FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--enable-logging=stderr", "--v=0", '--host-resolver-rules=MAP * ~NOTFOUND')

LAPTOP, PHONE = (1366, 900), (390, 844)

#: Appended to the report copy: records what the test reads back from the dumped DOM.
def _chromium(page: Path, work: Path, size: tuple[int, int], *mode: str) -> tuple[str, str, Path]:
    """Run Chromium on ``page``: (stdout, stderr, NetLog path)."""
    work.mkdir(parents=True, exist_ok=True)
    netlog = work / "netlog.json"
    done = subprocess.run(
        [CHROMIUM, *FLAGS, f"--user-data-dir={work / 'profile'}", f"--log-net-log={netlog}",
         f"--window-size={size[0]},{size[1]}", *mode, page.as_uri()],
        capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout, done.stderr, netlog


def _console(stderr: str) -> list[str]:
    """Console messages in Chromium's log (only the page under test runs scripts)."""
    return [line for line in stderr.splitlines() if ":CONSOLE" in line]


def _page_requests(netlog: Path) -> list[str]:
    """URLs of requests the page made (initiated by an origin) outside its own file."""
    log = json.loads(netlog.read_text(encoding="utf-8"))
    start = log["constants"]["logEventTypes"]["URL_REQUEST_START_JOB"]
    urls = []
    for event in log["events"]:
        params = event.get("params") or {}
        if event["type"] == start and "url" in params and \
                params.get("initiator") != "not an origin" and \
                not params["url"].startswith(("file:", "data:", "blob:")):
            urls.append(params["url"])
    return urls
