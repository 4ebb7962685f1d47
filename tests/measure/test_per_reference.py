"""What the stick derives from a reference alone, kept per frozen reference
(harness/measure/per_reference.py): kept only for a read-only reference, per object and mechanism,
bounded, read-only itself, and it changes no verdict or metric."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from mbh._adapters import get_adapter
from mbh._harness.measure import per_reference as memo
from mbh._harness.measure.metrics import case_metrics, reference_outputs
from mbh._harness.measure.verdict import judge, prepare_reference
from mbh._harness.model import scenario
from mbh._harness.references.build import reference_trajectory
from mbh._harness.run.case import simulate_case

#: Trajectory arrays (the reference store returns them read-only).
ARRAYS = ("times", "position", "quaternion", "velocity", "angular_velocity")


def writable_copy(reference):
    return dataclasses.replace(reference, **{name: getattr(reference, name).copy()
                                             for name in ARRAYS})


@pytest.fixture(scope="module")
def fourbar():
    mech = scenario.load("fourbar")
    return mech, reference_trajectory(mech)


def counting(calls: list):
    @memo.per_reference
    def derived(mech, reference, *args):
        calls.append(args)
        return len(calls)
    return derived


def test_stored_references_are_frozen_and_copies_are_not(fourbar):
    _, reference = fourbar
    assert memo.is_frozen(reference)
    assert not memo.is_frozen(writable_copy(reference))


def test_a_value_is_kept_per_frozen_reference_object_and_arguments(fourbar):
    mech, reference = fourbar
    calls = []
    derived = counting(calls)
    assert derived(mech, reference) == derived(mech, reference) == 1
    assert derived(mech, reference, 2.0) == 2  # other arguments: another value
    frozen_twin = dataclasses.replace(reference)  # the same arrays, another object
    assert derived(mech, frozen_twin) == 3
    copy = writable_copy(reference)
    assert derived(mech, copy) == 4 and derived(mech, copy) == 5  # never kept
    other = scenario.load("slider_crank")
    assert derived(other, reference) == 6  # another mechanism


def test_the_values_of_the_least_recently_used_reference_leave_first(fourbar, monkeypatch):
    mech, reference = fourbar
    monkeypatch.setattr(memo, "MAX_REFERENCES", 2)
    twins = [dataclasses.replace(reference) for _ in range(3)]  # frozen, distinct objects
    calls = []
    derived = counting(calls)
    for twin in twins:
        derived(mech, twin, "a")
    derived(mech, twins[2], "a")  # kept
    derived(mech, twins[1], "b")  # kept reference, new value
    derived(mech, twins[0], "a")  # the first left when the third came
    assert calls == [("a",)] * 3 + [("b",), ("a",)]


def test_kept_arrays_are_read_only(fourbar):
    mech, reference = fourbar
    prepare_reference(mech, reference)
    for series in reference_outputs(mech, reference).values():
        with pytest.raises(ValueError):
            series[0] = 0.0


def test_a_frozen_reference_gives_the_verdict_and_metrics_of_a_writable_copy(fourbar):
    """The kept values are the values: judging against the stored reference (kept, asked twice)
    and against a writable copy of it (never kept) agree bit for bit."""
    mech, reference = fourbar
    run = simulate_case(get_adapter("inhouse"), mech, "rk4+baumgarte", 1e-2, 1.0)
    prepare_reference(mech, reference)
    results = []
    for against in (reference, reference, writable_copy(reference)):
        judged = judge(mech, run, against)
        results.append((judged.status, judged.reason, judged.notes,
                        case_metrics(mech, judged, against)))
    assert results[0] == results[1] == results[2]
    assert np.isfinite(results[0][3]["max_energy_error_rel"])


def test_the_conditioning_a_failure_is_labelled_with_is_kept_and_unchanged():
    """A failed case's label reads the reference's conditioning: kept per frozen reference (the
    template computes it for every case), read-only, and the same numbers as computed afresh on
    a writable copy; the label of a run stopped at the double four-bar's first singular passage
    is the same against both."""
    from mbh._harness.measure.failure_label import label_failure, reference_conditioning
    from mbh._harness.model.trajectory import Trajectory
    from mbh._harness.neutral.conditioning import conditioning

    mech = scenario.load("double_fourbar")
    reference = reference_trajectory(mech)
    kept = reference_conditioning(mech, reference)
    assert reference_conditioning(mech, reference) is kept
    fresh = conditioning(mech, writable_copy(reference))
    assert np.array_equal(kept.ratio, fresh.ratio) and np.array_equal(kept.minima, fresh.minima)
    assert (kept.rank, kept.n_rows, kept.threshold) == (fresh.rank, fresh.n_rows, fresh.threshold)
    assert len(kept.minima), "the double four-bar passes singular positions"
    with pytest.raises(ValueError):
        kept.ratio[0] = 0.0
    stopped_at = float(kept.times[kept.minima[0]])
    failed = Trajectory.empty(len(mech.bodies), status="diverged", reason="test run",
                              failure_time=stopped_at)
    labels = [label_failure(mech, failed, against).reason
              for against in (reference, writable_copy(reference))]
    assert labels[0] == labels[1] and labels[0].startswith("singular configuration"), labels
