"""A new mechanism's first in-house answer takes the fast path or says why it cannot: drawn
mechanisms the code was not written around (a four-bar of parallel revolutes, Bennett's
overconstrained 4R loop typed from its description, a planar tree with spring-dampers), each
run with ``best`` long enough for ``loop=auto`` to generate its functions.

Either the generated functions serve (``kernel_calls`` ≤ 1 % of the right-hand sides), or a note
names why a function could not be had, and a function that would hand back every call is not
compiled (its source is checked at the start first, adapters/inhouse/codegen/generated.py).  The first
two have redundant equations; their runs must still be ``ok`` and on the constraints.
"""

from __future__ import annotations

import pytest

from mbh._adapters import get_adapter
from mbh._adapters.inhouse.codegen import generated_store
from mbh._harness.measure.metrics import constraint_violations
from mbh._harness.model.timegrid import sample_times
from tests.helpers import bennett_linkage, parallel_revolute_fourbar, spring_damper_tree

MECHANISMS = {"fourbar_4r": parallel_revolute_fourbar, "bennett": bennett_linkage,
              "spring_tree": spring_damper_tree}
#: Largest joint gap along the run by the stick, m: rk4+direct projects to 1e-15 (proj_tol)
#: every step.  Measured (2026-11-29): 2.0e-15 (four-bar), 1.8e-15 (Bennett), 2.5e-16 (tree);
#: the bound leaves a factor of 50 for another machine's round-off.
CONSTRAINT_BOUND = 1e-13


@pytest.mark.parametrize("name", sorted(MECHANISMS))
def test_a_new_mechanisms_best_run_is_served_or_says_why(name, tmp_path, monkeypatch):
    monkeypatch.setenv("MBH_GENERATED_DIR", str(tmp_path))
    mech = MECHANISMS[name]()
    adapter = get_adapter("inhouse")
    run = adapter.simulate(mech, "best", 1e-3, 0.5, sample_times(1e-3, 0.5))
    assert run.status == "ok", run.reason
    counters = run.counters
    why = [note for note in run.notes if note.startswith("not generated: acceleration")]
    assert why or counters["kernel_calls"] <= counters["rhs_evals"] // 100, run.notes
    declined = [note for note in run.notes if "guards decline at the start" in note]
    compiled = [path.read_text() for mark in tmp_path.glob(f"*/*/{generated_store.USED}")
                for path in mark.parent.glob("*.py")]
    for note in declined:
        names = note.removeprefix("not generated: ").split(" (")[0].split(", ")
        for function in names:
            assert not [text for text in compiled
                        if f"def {function.replace(' ', '_')}(" in text], note
    # The stick's joint equations on the body states (harness/measure), not the in-house ones.
    assert constraint_violations(mech, run)["max_constraint_violation"] <= CONSTRAINT_BOUND


def test_the_drawn_mechanisms_are_what_their_descriptions_say():
    """Rank, mobility and redundant equations of the drawn mechanisms (the in-house rank
    analysis at the assembled start): Bennett's loop has mobility 1 with Grübler's count −2."""
    from mbh._adapters.inhouse.bodies.kinematics import check

    found = {name: check(make()) for name, make in MECHANISMS.items()}
    summary = {name: (row["mobility"], row["grubler_mobility"], row["redundant_equations"])
               for name, row in found.items()}
    assert summary == {"fourbar_4r": (1, -2, 3), "bennett": (1, -2, 3),
                       "spring_tree": (3, 3, 0)}
    assert all(row["assembly_residual"] < 1e-12 for row in found.values())
