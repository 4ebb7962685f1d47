"""A results root that is read-only or full (issue 31 item 5; docs/formats/store.md, "A results
root that cannot be written").

``mbh run`` must fail before any case runs, naming the root and the problem, and change nothing
already stored; a disk that fills during a run must stop it with a clear message, mark it
``interrupted`` if the manifest can still be written, and leave every stored case intact and
resumable.

Read-only roots: ``chmod 0o555`` where that stops writes; these tests may run as root, for whom
chmod stops nothing, so :func:`read_only` then makes every store write fail with EROFS instead
(monkeypatching the store's atomic write, as a read-only mount would).  A full disk is always
simulated: the store's atomic write raises ENOSPC.
"""

from __future__ import annotations

import contextlib
import errno
import io
import os
import shutil
from pathlib import Path

import pytest

from mbh._harness import cli
from mbh._harness.run.campaign import run_campaign
from mbh._harness.run.spec import load_campaign
from mbh._harness.store import files, location
from mbh._harness.store.manifest import list_runs
from mbh._harness.store.problems import StoreError
from mbh._harness.store.runs import RunStore, load_run
from tests.store.store_cases import RUNNABLE_CAMPAIGN, SPECS, campaign, row_for, trajectory

CAMPAIGN = RUNNABLE_CAMPAIGN


def failing_writes(monkeypatch, code: int, after: int = 0, only=("",)) -> None:
    """Make the store's atomic writes raise OSError(``code``) once ``after`` writes whose path
    contains one of ``only`` have succeeded (every later one fails, as on a full disk)."""
    real, done = files._atomic_write, []

    def write(path: Path, content) -> None:
        if any(part in str(path) for part in only):
            if len(done) >= after:
                raise OSError(code, os.strerror(code), str(path))
            done.append(path)
        real(path, content)

    monkeypatch.setattr(files, "_atomic_write", write)


def read_only(root: Path, monkeypatch) -> str:
    """Make ``root`` refuse writes; returns how ("chmod" or "EROFS simulated": as root)."""
    root.chmod(0o555)
    try:
        (root / ".can-i-write").touch()
    except PermissionError:
        return "chmod"
    (root / ".can-i-write").unlink()
    root.chmod(0o755)
    failing_writes(monkeypatch, errno.EROFS)
    return "EROFS simulated"


def snapshot(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*"))
            if p.is_file()}


def stored_run(root: Path, status: str) -> RunStore:
    """A run of one stored case under ``root``, finished with ``status``."""
    store = RunStore.create(campaign(), root)
    store.add(row_for(SPECS[0]), trajectory())
    store.finish(status)
    return store


def mbh(*argv) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        status = cli.main([str(a) for a in argv])
    return status, out.getvalue(), err.getvalue()


@pytest.fixture
def campaign_file(tmp_path) -> Path:
    path = tmp_path / "tiny.toml"
    path.write_text(CAMPAIGN, encoding="utf-8")
    return path


# --- the early check --------------------------------------------------------------------------

def test_a_root_that_is_a_file_is_refused(tmp_path):
    root = tmp_path / "results"
    root.write_text("not a folder")
    with pytest.raises(StoreError, match=rf"results root {root}: not a folder"):
        RunStore.check_writable(root)


def test_a_root_under_a_file_is_refused(tmp_path):
    (tmp_path / "file").write_text("")
    root = tmp_path / "file" / "results"
    with pytest.raises(StoreError, match=rf"results root {root}: .*cannot write: Not a directory"):
        RunStore.check_writable(root)


def test_a_read_only_root_is_refused(tmp_path, monkeypatch):
    root = tmp_path / "results"
    root.mkdir()
    how = read_only(root, monkeypatch)
    meaning = "no permission" if how == "chmod" else "the file system is read-only"
    try:
        with pytest.raises(StoreError, match=rf"results root {root}: .*cannot write: .*{meaning}"):
            RunStore.check_writable(root)
    finally:
        root.chmod(0o755)


def test_a_full_disk_is_refused(tmp_path, monkeypatch):
    failing_writes(monkeypatch, errno.ENOSPC)
    with pytest.raises(StoreError, match=r"results root .*No space left on device \(the disk "
                                         r"is full\)"):
        RunStore.check_writable(tmp_path / "results")


def test_a_nearly_full_disk_is_refused(tmp_path, monkeypatch):
    free = location.MIN_FREE_BYTES - 1
    monkeypatch.setattr(location.shutil, "disk_usage",
                        lambda path: shutil._ntuple_diskusage(10**12, 10**12 - free, free))
    with pytest.raises(StoreError, match=r"only 16\.0 MiB free on its disk; a run needs at "
                                         r"least 16 MiB"):
        RunStore.check_writable(tmp_path / "results")


def test_mbh_run_on_a_read_only_root_fails_before_any_case_and_keeps_what_is_stored(
        tmp_path, monkeypatch, campaign_file):
    root = tmp_path / "results"
    stored_run(root, "complete")
    before = snapshot(root)
    read_only(root, monkeypatch)
    try:
        status, out, err = mbh("run", campaign_file, "--root", root, "--quiet")
    finally:
        root.chmod(0o755)
    assert status == 2 and out == "", (status, out, err)
    assert err.startswith(f"mbh: results root {root}: "), err
    assert snapshot(root) == before  # no new run folder, nothing changed


def test_mbh_run_on_a_read_only_root_fails_before_building_a_reference(tmp_path, monkeypatch):
    """The root is checked first: a scene without a stored reference would otherwise have its
    reference built (seconds to minutes) before the run failed."""
    shipped = Path(__file__).resolve().parents[2] / "scenarios" / "fourbar.toml"
    text = shipped.read_text(encoding="utf-8")
    assert text.count("duration = 4.0\n") == 1
    (tmp_path / "my_fourbar.toml").write_text(text.replace("duration = 4.0\n", "duration = 3.0\n"),
                                              encoding="utf-8")
    campaign_path = tmp_path / "mine.toml"
    campaign_path.write_text(CAMPAIGN.replace('"fourbar"', '"my_fourbar.toml"'), encoding="utf-8")
    references = tmp_path / "references"
    monkeypatch.setenv("MBH_CACHE_DIR", str(references))
    root = tmp_path / "results"
    root.mkdir()
    read_only(root, monkeypatch)
    try:
        status, out, err = mbh("run", campaign_path, "--root", root, "--quiet")
    finally:
        root.chmod(0o755)
    assert status == 2 and err.startswith(f"mbh: results root {root}: "), (status, err)
    assert not references.exists() or not any(references.iterdir())  # nothing built


def test_resuming_on_a_read_only_root_fails_early_and_changes_nothing(tmp_path, monkeypatch):
    root = tmp_path / "results"
    stopped = stored_run(root, "interrupted")
    before = snapshot(root)
    read_only(root, monkeypatch)
    try:
        with pytest.raises(StoreError, match=rf"results root {root}: "):
            RunStore.open(stopped.run_id, root).lock()
    finally:
        root.chmod(0o755)
    assert snapshot(root) == before


# --- a disk that fills during a run -----------------------------------------------------------

@pytest.mark.parametrize("manifest_writable", [True, False])
def test_a_disk_full_mid_run_stops_it_and_keeps_every_stored_case(tmp_path, monkeypatch,
                                                                  manifest_writable):
    root = tmp_path / "results"
    store = RunStore.create(campaign(), root)
    store.lock()
    store.add(row_for(SPECS[0]), trajectory())
    store.add(row_for(SPECS[1]), trajectory())
    # full: trajectories and parts fail from here on (the small manifest may still fit)
    failing_writes(monkeypatch, errno.ENOSPC,
                   only=("/trajectories/", "/cases/") if manifest_writable else ("",))
    with pytest.raises(StoreError) as raised:
        store.add(row_for(SPECS[2]), trajectory())
    message = str(raised.value)
    marked = "marked interrupted" if manifest_writable else "left marked running"
    assert "No space left on device (the disk is full)" in message
    assert f"case {SPECS[2].case_id!r} is not stored and the run stops: run {store.run_id} is " \
           f"{marked}" in message
    assert "and keeps its 2 stored cases intact" in message
    assert message.endswith(f"resume it with: mbh run demo --resume {store.run_id}")

    monkeypatch.undo()  # space freed
    reopened = RunStore.open(store.run_id, root)
    assert reopened.manifest["status"] == ("interrupted" if manifest_writable else "running")
    assert list(reopened.cases()["case_id"]) == [SPECS[0].case_id, SPECS[1].case_id]
    assert reopened.problems == []
    reopened.lock()  # the stopped writer released its lock
    reopened.mark_running()
    reopened.add(row_for(SPECS[2]), trajectory())
    reopened.finish("complete")
    assert list(RunStore.open(store.run_id, root).cases()["case_id"]) == \
        [SPECS[0].case_id, SPECS[1].case_id, SPECS[2].case_id]


def test_a_campaign_whose_disk_fills_stops_and_resumes_to_every_case(tmp_path, monkeypatch,
                                                                     campaign_file):
    """End to end through the campaign runner: the third case's part cannot be written."""
    root = tmp_path / "results"
    tiny = load_campaign(campaign_file)
    failing_writes(monkeypatch, errno.ENOSPC, after=2, only=("/cases/part-",))
    with pytest.raises(StoreError, match="the run stops"):
        run_campaign(tiny, workers=1, root=root, quiet=True)
    (run_id,) = [m["run_id"] for m in list_runs(root)]
    assert list_runs(root)[0]["status"] == "interrupted"
    assert len(load_run(run_id, root)) == 2
    monkeypatch.undo()
    store = run_campaign(tiny, workers=1, root=root, resume=run_id, quiet=True)
    assert store.manifest["status"] == "complete"
    assert sorted(store.cases()["case_id"]) == sorted(spec.case_id for spec in tiny.cases)
