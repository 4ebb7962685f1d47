"""The status vocabularies (mbh._harness.common.status): members are their plain strings, so every
file the store writes keeps its bytes, and a string read back compares equal to its member."""

from __future__ import annotations

import json

import pandas as pd
import pyarrow.parquet as pq
import pytest

from mbh._adapters.base import RunFailure
from mbh._harness.common import jsonout
from mbh._harness.common.status import CaseStatus, IntegratorState, RunStatus
from mbh._harness.model.trajectory import STATUSES, Trajectory
from mbh._harness.store.files import write_json
from mbh._harness.store.rows import case_frame, row_table
from mbh._harness.store.schema import CASE_COLUMNS


def test_the_stored_vocabularies_are_unchanged():
    assert [str(s) for s in CaseStatus] == ["ok", "diverged", "failed", "unsupported", "timeout",
                                            "crashed"]
    assert [str(s) for s in RunStatus] == ["running", "complete", "interrupted", "unreadable"]
    assert [str(s) for s in IntegratorState] == ["running", "diverged", "failed"]
    assert STATUSES == tuple(CaseStatus)


def test_a_member_writes_as_its_plain_string():
    assert json.dumps(CaseStatus.OK) == '"ok"'
    assert jsonout.dumps({"status": RunStatus.COMPLETE}, indent=None) == '{"status": "complete"}'
    assert f"{CaseStatus.TIMEOUT}" == "timeout" and ", ".join(STATUSES[:2]) == "ok, diverged"


def test_a_row_written_with_a_member_reads_back_as_the_plain_string(tmp_path):
    path = tmp_path / "row.parquet"
    pq.write_table(row_table({"case_id": "c", "status": CaseStatus.DIVERGED}, CASE_COLUMNS), path)
    stored = pq.read_table(path).column("status").to_pylist()
    assert stored == ["diverged"] and type(stored[0]) is str
    for frame in (pd.read_parquet(path), case_frame({"status": CaseStatus.DIVERGED})):
        assert type(frame["status"].iloc[0]) is str
        assert (frame["status"] == CaseStatus.DIVERGED).all()
        assert frame["status"].isin((CaseStatus.DIVERGED, CaseStatus.FAILED)).all()


def test_a_manifest_written_with_a_member_holds_the_plain_string(tmp_path):
    path = tmp_path / "manifest.json"
    write_json(path, {"status": RunStatus.INTERRUPTED})
    assert json.loads(path.read_bytes()) == {"status": "interrupted"}


def test_a_trajectory_reads_a_plain_status_as_its_member():
    empty = Trajectory.empty(1, status="failed", reason="why")
    assert empty.status is CaseStatus.FAILED
    with pytest.raises(ValueError, match="one of ok, diverged, failed"):
        Trajectory.empty(1, status="running")


def test_a_stopped_integrator_names_the_case_status_its_run_ends_with():
    for state in (IntegratorState.DIVERGED, IntegratorState.FAILED):
        assert RunFailure(state, "why").status is CaseStatus(state)
    with pytest.raises(ValueError, match="'failed' or 'diverged'"):
        RunFailure(IntegratorState.RUNNING, "still stepping")
