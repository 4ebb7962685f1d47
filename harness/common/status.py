"""The closed vocabularies of status: how a case ended (:class:`CaseStatus`), where a stored run
stands (:class:`RunStatus`) and an in-house integrator's own state while it steps
(:class:`IntegratorState`).

Each is an :class:`enum.StrEnum`: a member *is* its value string (``CaseStatus.OK == "ok"``,
``json.dumps(CaseStatus.OK) == '"ok"'``), so Parquet files, JSON, manifests and every stored run
keep their exact bytes, and a status read back from them (a plain string) compares equal to its
member.  The integer codes of the in-house compiled loops
(:mod:`mbh._adapters.inhouse.stepping.loop_codes`) are a numba matter and stay integers.
"""

from __future__ import annotations

from enum import StrEnum

__all__ = ["CaseStatus", "RunStatus", "FINISHED_RUN_STATUSES", "IntegratorState"]


class CaseStatus(StrEnum):
    """How a case ended, the same vocabulary for every adapter (the run loop of
    :mod:`mbh._adapters.base` classifies; the campaign runner adds the last two)."""

    #: Every state the run produced and the loop read was finite and within bounds.
    OK = "ok"
    #: A non-finite or exploding state (position, orientation, velocity or angular velocity),
    #: found by the common check or the engine's own.
    DIVERGED = "diverged"
    #: The method stopped (a solver failure, or an exception raised during the run).
    FAILED = "failed"
    #: The engine cannot represent the mechanism or the method.
    UNSUPPORTED = "unsupported"
    #: The case ran out of its time budget (campaign runner).
    TIMEOUT = "timeout"
    #: The worker process running the case died (campaign runner).
    CRASHED = "crashed"


class RunStatus(StrEnum):
    """Where a stored run stands: its manifest's ``status``."""

    #: Started (or resumed) and not finished; also a run whose process was killed.
    RUNNING = "running"
    #: Every case ran and the one-file exports were written.
    COMPLETE = "complete"
    #: Stopped before its end (a signal, a disk that filled); ``--resume`` completes it.
    INTERRUPTED = "interrupted"
    #: Never written: what the listing of the stored runs gives a run whose manifest cannot be
    #: read (:func:`mbh._harness.store.manifest.list_runs`).
    UNREADABLE = "unreadable"


#: The statuses a run is finished with (:meth:`mbh._harness.store.runs.RunStore.finish`).
FINISHED_RUN_STATUSES = (RunStatus.COMPLETE, RunStatus.INTERRUPTED)


class IntegratorState(StrEnum):
    """An in-house integrator's own state (:class:`mbh._adapters.integrators.Integrator`): it
    steps while ``running``; a stopped integrator names the case status its run ends with."""

    RUNNING = "running"
    DIVERGED = CaseStatus.DIVERGED.value
    FAILED = CaseStatus.FAILED.value
