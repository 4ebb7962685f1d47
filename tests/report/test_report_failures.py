"""The report section "Where methods fail" (harness/report/failures.py).

A synthetic run of double_fourbar (rows written by hand through the store, no engine run): one
accurate case, a failure 4.4 ms before the first flattened passage (IDA's measured failure time),
a failure between the passages, an inaccurate ok case, an unsupported case, and sweep rows with an
explicit method stable only at a small step.  The section is built from it, and the conditioning
of the shipped reference is checked against the tip's passages through y = 0.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from mbh._adapters import get_adapter
from mbh._harness.model import scenario
from mbh._harness.run.spec import CaseSpec
from mbh._harness.run.row import error_row
from mbh._harness.model.outputs import output_series
from mbh._harness.references.build import reference_trajectory
from mbh._harness.report import build, failures
from mbh._harness.store.runs import RunStore

SCENE = "double_fourbar"
T_END = 2.0
UNSUPPORTED_REASON = "synthetic: this engine has no planar revolute joint"
#: A note naming an engine's limit, as the Pinocchio adapter writes it (longer than a quote).
LIMIT_NOTE = ("engine limit: 2718 of 4000 pin.constraintDynamics solves ended unconverged "
              "(relative residual above 0.01, largest 128, after at most 20 proximal iterations)")


def _spec(adapter: str, method: str, dt: float) -> CaseSpec:
    return CaseSpec(SCENE, adapter, method, dt, T_END)


#: (spec, changes to the error row) of the synthetic run.
ROWS = (
    (_spec("inhouse", "best", 1e-3), {"status": "ok", "reason": "", "main_output_error": 1e-9,
                                      "accurate": True, "wall_time_s": 1.0}),
    (_spec("inhouse", "ida", 1e-3), {"status": "failed", "failure_time": 0.7096,
                                     "reason": "IDA flag -4: convergence test failed"}),
    (_spec("inhouse", "rk4+direct", 1e-2), {"status": "diverged", "failure_time": 1.0,
                                            "reason": "synthetic divergence"}),
    (_spec("mujoco", "default", 1e-3), {"status": "ok", "reason": "", "main_output_error": 3e-2,
                                        "accurate": False, "wall_time_s": 0.2}),
    (_spec("pybullet", "default", 1e-3), {"status": "unsupported", "reason": UNSUPPORTED_REASON}),
    (_spec("pinocchio", "best", 1e-3), {"status": "ok", "reason": "", "main_output_error": 2e-3,
                                        "accurate": False, "wall_time_s": 0.3,
                                        "notes": json.dumps([LIMIT_NOTE])}),
)
#: Sweep rows: an explicit and an implicit method's largest stable step.
SWEEPS = (
    {"sweep_id": f"{SCENE}|inhouse|default", "scenario": SCENE, "adapter": "inhouse",
     "method": "default", "largest_stable_dt": 2.5e-4, "criterion": "ok and accurate",
     "tried": '[[0.01, "diverged", "NaN"], [0.00025, "ok", 1e-06]]'},
    {"sweep_id": f"{SCENE}|exudyn|default", "scenario": SCENE, "adapter": "exudyn",
     "method": "default", "largest_stable_dt": 1e-2, "criterion": "ok and accurate",
     "tried": '[[0.01, "ok", 1e-05]]'},
)


class _Campaign:
    """What :meth:`RunStore.create` reads of a campaign (its cases name the scene, so the
    manifest records its content hash)."""

    def __init__(self):
        self.name, self.path = "failmap_test", Path("failmap_test.toml")
        self.cases, self.sweep = tuple(spec for spec, _ in ROWS), None
        self.text = 'description = "synthetic hard run"\naccuracy = 1e-3\n'


@pytest.fixture(scope="module")
def synthetic_run(tmp_path_factory) -> tuple[Path, str]:
    root = tmp_path_factory.mktemp("failmap") / "results"
    store = RunStore.create(_Campaign(), root)
    for spec, changes in ROWS:
        store.add({**error_row(spec, "failed", ""), **changes}, None)
    for row in SWEEPS:
        store.add_sweep(row)
    store.set_calibration(1.0)
    store.finish("complete")
    return root, store.run_id


@pytest.fixture(scope="module")
def scene(synthetic_run) -> failures.FailureScene:
    root, run_id = synthetic_run
    report = build.collect(run_id, root=root, built_at="2001-02-03T04:05:06+00:00")
    assert [s.scenario for s in report.failure_scenes] == [SCENE]
    assert report.omitted.get("failures") is None
    return report.failure_scenes[0]


def test_reading_places_the_failure_at_the_passage_and_names_the_unsupported_engine(scene):
    reading = " ".join(scene.reading)
    # The two flattened passages within 2 s (measured on the shipped reference: 0.714, 1.228 s).
    assert "at 2 near-singular position(s) within the run: t = 0.714 s" in reading
    assert "t = 1.228 s" in reading
    assert ("Fail at a near-singular position (within ±0.05 s of one): inhouse ida dt=0.001 "
            "failed at 0.7096 s (passage at 0.714 s)") in reading
    # 1.0 s is 0.23 s from either passage: away from them.
    assert ("Fail away from the near-singular positions: inhouse rk4+direct dt=0.01 diverged "
            "at 1 s") in reading
    assert ("Pass the near-singular positions (ok and within 0.001 at some step, running past "
            "t = 0.714 s): inhouse best (dt 0.001: 1e-09).") in reading
    assert "never within 0.001 (ok and inaccurate, reported as such): mujoco default " \
           "(smallest error 0.03)" in reading
    # An inaccurate method's row that names its engine's limit carries it into the reading.
    assert f"pinocchio best (smallest error 0.002; {LIMIT_NOTE[:89]}…)" in reading
    assert f"Cannot represent the scene (unsupported): pybullet ({UNSUPPORTED_REASON})." in reading
    assert ("Largest stable step: explicit integration up to 0.00025 s (inhouse default); "
            "implicit integration up to 0.01 s (exudyn default). Explicit integration needs "
            "steps 40× smaller here.") in reading


def test_tables_hold_every_case_and_sweep(scene):
    outcomes = {row[:2]: row[2:] for row in scene.outcomes.rows}
    assert scene.outcomes.columns[2:] == ("dt 0.001 s", "dt 0.01 s")
    assert outcomes[("inhouse", "ida")] == ("failed at 0.7096 s", None)
    assert outcomes[("inhouse", "rk4+direct")] == (None, "diverged at 1 s")
    assert outcomes[("inhouse", "best")] == ("accurate (1e-09)", None)
    assert outcomes[("mujoco", "default")] == ("inaccurate (0.03)", None)
    assert outcomes[("pybullet", "default")] == ("unsupported", None)
    stable = {row[:2]: row[2:] for row in scene.stable_steps.rows}
    assert stable[("inhouse", "default")][:2] == ("explicit", 2.5e-4)
    assert stable[("inhouse", "default")][3] == "0.01 diverged, 0.00025 ok (1e-06)"
    assert stable[("exudyn", "default")][:2] == ("implicit", 1e-2)


def test_figure_marks_both_failures(scene):
    figure = scene.conditioning
    assert figure is not None
    # One vertical line above and one marker below per stopped case.
    assert figure.svg.count('id="failure-time') == 4
    assert "inhouse ida dt=0.001 failed at 0.7096 s" in figure.alt
    assert "near-singular positions at 0.714 s, 1.228 s" in figure.alt


def test_html_and_pdf_contain_the_section(synthetic_run, tmp_path):
    import pypdfium2

    root, run_id = synthetic_run
    written = build.build_report(run_id, out=tmp_path, root=root,
                                 built_at="2001-02-03T04:05:06+00:00")
    html = written["html"].read_text(encoding="utf-8")
    assert '<section id="failures">' in html and "<h2>Where methods fail</h2>" in html
    assert html.index('<section id="stability">') < html.index('<section id="failures">') \
        < html.index('<section id="histories">')
    assert "failed at 0.7096 s (passage at 0.714 s)" in html
    document = pypdfium2.PdfDocument(str(written["pdf"]))
    text = " ".join(" ".join(document[i].get_textpage().get_text_range().split())
                    for i in range(len(document)))
    assert "Where methods fail" in text
    assert "Cannot represent the scene (unsupported): pybullet" in text


def test_no_section_without_hard_or_swept_scenes(tmp_path):
    class Benign(_Campaign):
        def __init__(self):
            super().__init__()
            self.name, self.cases = "benign", (CaseSpec("fourbar", "inhouse", "best", 1e-3, 0.2),)

    store = RunStore.create(Benign(), tmp_path)
    store.add({**error_row(Benign().cases[0], "ok", ""), "main_output_error": 1e-9}, None)
    store.finish("complete")
    report = build.collect(store.run_id, root=tmp_path, built_at="2001-02-03T04:05:06+00:00")
    assert report.failure_scenes == []
    assert '<section id="failures">' not in build.render_html(report)


def test_conditioning_minima_are_the_flattened_passages():
    mech = scenario.load(SCENE)
    reference = reference_trajectory(mech)
    cond = failures.conditioning(mech, reference)
    assert (cond.rank, cond.n_rows) == (14, 14)
    y = output_series(mech, reference, "tip_y")
    t = reference.times
    i = np.flatnonzero(np.sign(y[:-1]) != np.sign(y[1:]))
    crossings = t[i] - y[i] * (t[i + 1] - t[i]) / (y[i + 1] - y[i])
    # Ten passages through y = 0 in 10 s, each one minimum of σ_r/σ_1.
    assert len(crossings) == 10 and len(cond.minima) == 10
    # The minima sit on the 1 ms sample grid: each within half a sample of the interpolated
    # crossing (measured at most 4.1e-4 s; bound 5e-4 s, half the 1e-3 s sample spacing).
    assert np.max(np.abs(cond.minimum_times - crossings)) <= 5e-4
    # Away from the passages (> 0.1 s) the curve stays far above the threshold (measured
    # smallest 0.0745, 45× the threshold 0.00167): no spurious near-singular position.
    away = np.all(np.abs(t[:, None] - crossings[None, :]) > 0.1, axis=1)
    assert cond.threshold == pytest.approx(failures.SINGULAR_DROP * np.median(cond.ratio))
    assert cond.ratio[away].min() > 10 * cond.threshold


@pytest.mark.parametrize("adapter, method, kind", [
    ("inhouse", "best", "explicit"), ("inhouse", "default", "explicit"),
    ("inhouse", "bdf4+direct:tol=1e-10", "implicit"), ("inhouse", "ida", "implicit"),
    ("exudyn", "default", "implicit"), ("pinocchio", "best", "explicit"),
    ("mujoco", "implicitfast", None), ("inhouse", "no-such-method", None),
])
def test_integration_kind(adapter, method, kind):
    assert failures.integration_kind(adapter, method) == kind


@pytest.mark.parametrize("alias", sorted(failures._INHOUSE_ALIAS_KIND))
def test_the_report_knows_what_each_inhouse_alias_resolves_to(alias):
    # A report never asks an adapter, so its table of the in-house aliases is checked here
    # against the adapter's own resolution.
    resolved = get_adapter("inhouse").method_spec(alias)[0].name
    assert failures.integration_kind("inhouse", resolved) == \
        failures.integration_kind("inhouse", alias) is not None


def test_hard_campaign_covers_every_hard_scene():
    from mbh._adapters import adapter_names
    from mbh._harness.run.spec import load_campaign

    hard = load_campaign("hard")
    scenes = {name for name in scenario.scenario_names()
              if failures.HARD_TAG in scenario.load(name).tags}
    assert SCENE in scenes
    cases = {(c.scenario, c.adapter, c.method, c.dt) for c in hard.cases}
    for name in scenes:
        # Three decades of steps from the scene's evaluation step down (1e-2 s unless it
        # declares a finer sample_step: Andrews' squeezer 1e-3 s).
        base = scenario.load(name).sample_step
        steps = {c.dt for c in hard.cases if c.scenario == name}
        decades = [dt for dt in steps if any(dt == pytest.approx(base / 10 ** k) for k in range(3))]
        assert len(decades) == 3, (name, sorted(steps))
        for adapter in adapter_names():
            for method in ("default", "best"):
                assert {(name, adapter, method, dt) for dt in decades} <= cases
    assert scenes <= set(hard.sweep.scenarios)  # plus family members (not listed by name)
    assert all({"default", "best"} <= set(hard.sweep.methods[a]) for a in adapter_names())
