"""Bad tolerance files, tried by the thousand (issue 31 item 5): :class:`mbh._harness.testing.tolerances.Tolerances`.

Every example is the project's own tolerance file (tests/acceptance/tolerances.toml) or the
documented example, mutated by Hypothesis — wrong types, NaN and ±inf, negative and subnormal
tolerances, integers beyond the double range, unknown keys, bad step keys, output tables
replaced by junk, ``order`` bands of every shape — sometimes with its TOML text broken too.  For
every example the loader must return tolerances that every case can be matched against, or raise
one :class:`ToleranceError` whose message starts with the file and names the field.

Profiles: the default suite tries :data:`DEFAULT_EXAMPLES` inputs, derandomized; the ``slow``
mark tries :data:`SLOW_EXAMPLES` with fresh randomness (the style of tests/model/test_fuzz.py).
"""

from __future__ import annotations

import copy
import math
import tomllib

import pytest
from hypothesis import event, example, given, settings
from hypothesis import strategies as st

from mbh._harness.run.spec import CaseSpec
from mbh._harness.testing.cases import ToleranceError
from mbh._harness.testing.tolerances import CaseTolerance, Tolerances
from tests.helpers import ROOT
from tests.fuzzing import BASE, BREAKS, HUGE, NAMES, NUMBERS, VALUES, fuzzed_file, toml_document

DEFAULT_EXAMPLES = 300
SLOW_EXAMPLES = 3000

TOLERANCE_DEFAULT = settings(BASE, max_examples=DEFAULT_EXAMPLES)
TOLERANCE_SLOW = settings(BASE, max_examples=SLOW_EXAMPLES, derandomize=False)

DOCUMENTED = """
[fourbar.inhouse."rk4+direct"]
outputs = { crank_angle = { atol = 4e-9 } }
energy_error = 5e-9
[fourbar.inhouse."rk4+direct".dt."1e-2"]
outputs = { crank_angle = { atol = 4e-5 } }
energy_error = 7e-5
[fourbar.mujoco.best]
outputs = { crank_angle = { atol = 2e-6 } }
constraint_violation = 2e-6
order = [1.7, 2.3]
[fourbar.mujoco.default]
status = "failed"
["*"."*"."*"]
status = "ok"
"""
BASES = [tomllib.loads((ROOT / "tests" / "acceptance" / "tolerances.toml").read_text()),
         tomllib.loads(DOCUMENTED)]

#: Cases every loaded file is matched against (the merge must not fail on any of them).
SPECS = [CaseSpec("fourbar", "mujoco", "best", 1e-3, 1.0),
         CaseSpec("fourbar", "inhouse", "rk4+direct", 1e-2, 1.0),
         CaseSpec("slider_crank", "pybullet", "default", 1e-3, 0.5)]

TOLERANCE_NUMBERS = st.one_of(st.sampled_from([1e-9, 2e-6, 0.0, 1.0]), NUMBERS, HUGE)
FIELD_VALUES = {
    "status": st.one_of(st.sampled_from(["ok", "failed", "diverged", "OK", "", "crashed"]),
                        VALUES),
    "outputs": st.one_of(
        st.dictionaries(st.one_of(NAMES, st.just("crank_angle")),
                        st.one_of(st.dictionaries(st.sampled_from(["atol", "rtol", "btol", ""]),
                                                  TOLERANCE_NUMBERS, max_size=3), VALUES),
                        max_size=2), VALUES),
    "constraint_violation": TOLERANCE_NUMBERS, "energy_error": TOLERANCE_NUMBERS,
    "order": st.one_of(st.lists(TOLERANCE_NUMBERS, min_size=0, max_size=3), VALUES),
    "dt": st.one_of(st.dictionaries(st.sampled_from(["1e-2", "1e-3", "0", "-1e-3", "nan", "inf",
                                                     "1e400", "x", "", "1_0", " 1e-3"]),
                                    st.one_of(st.dictionaries(
                                        st.sampled_from(["outputs", "energy_error", "dt",
                                                         "status"]),
                                        TOLERANCE_NUMBERS, max_size=2), VALUES), max_size=2),
                    VALUES),
    "unknown": VALUES,
}
KEYS = st.sampled_from(sorted(FIELD_VALUES))


def entries(document: dict) -> list[dict]:
    """Every table of the document: scenes, adapters, method entries, their outputs and steps."""
    found, level = [document], [document]
    for _ in range(3):
        level = [t for table in level for t in table.values() if isinstance(t, dict)]
        found += level
    found += [t for table in level for key in ("outputs", "dt")
              if isinstance(table.get(key), dict) for t in [table[key], *table[key].values()]
              if isinstance(t, dict)]
    return found


@st.composite
def mutated(draw) -> dict:
    """A base file with one to three mutations (drawn values deep-copied in)."""
    document = copy.deepcopy(draw(st.sampled_from(BASES)))
    for _ in range(draw(st.sampled_from([1, 1, 1, 2, 3]))):
        table = draw(st.sampled_from(entries(document)))
        kind = draw(st.sampled_from(["set", "set", "set", "delete", "rename"]))
        if kind == "set":
            own = table and draw(st.integers(0, 3)) > 0
            key = draw(st.sampled_from(sorted(table)) if own else KEYS)
            table[key] = copy.deepcopy(draw(FIELD_VALUES.get(key, VALUES)))
        elif table:
            key = draw(st.sampled_from(sorted(table)))
            value = table.pop(key)
            if kind == "rename":
                table[draw(st.one_of(NAMES, st.just("*"), KEYS))] = value
    return document


@st.composite
def tolerance_text(draw) -> str:
    text = toml_document(draw(mutated()))
    for _ in range(draw(st.sampled_from([0, 0, 0, 0, 1, 2]))):
        at = draw(st.integers(0, len(text)))
        text = text[:at] + draw(BREAKS) + text[at + draw(st.integers(0, 5)):]
    return text


# -- the oracle ----------------------------------------------------------------------------------
def assert_usable(tolerance: CaseTolerance) -> None:
    for output in tolerance.outputs.values():
        assert math.isfinite(output.atol) and output.atol >= 0, tolerance
        assert math.isfinite(output.rtol) and output.rtol >= 0, tolerance
    for bound in (tolerance.constraint_violation, tolerance.energy_error):
        assert bound is None or (math.isfinite(bound) and bound > 0), tolerance
    if tolerance.order is not None:
        assert tolerance.order[0] <= tolerance.order[1], tolerance


def assert_clear(error: ToleranceError, path) -> None:
    """``FILE: FIELD: PROBLEM`` (or ``FILE: PROBLEM`` for the whole file)."""
    message = str(error)
    assert message.startswith(f"{path}: "), message
    assert message[len(f"{path}: "):].strip(), message


def load_or_clear_error(text: str) -> None:
    with fuzzed_file(text) as path:
        try:
            tolerances = Tolerances(path)
        except ToleranceError as error:
            assert_clear(error, path)
            event("tolerances: rejected")
            return
        for spec in SPECS:
            try:
                assert_usable(tolerances.for_case(spec))
            except ToleranceError as error:  # no entry matches the case
                assert_clear(error, path)
    event("tolerances: loaded")


@TOLERANCE_DEFAULT
@given(text=tolerance_text())
# Found: an integer beyond the double range raised OverflowError (math.isfinite).
@example(text=toml_document({"a": {"b": {"c": {"energy_error": 10**400}}}}))
@example(text=toml_document({"a": {"b": {"c": {"order": [10**400, 1]}}}}))
# Found: tomllib raised ValueError for a 5000-digit integer and RecursionError for deep arrays.
@example(text="x = " + "9" * 5000)
@example(text="x = " + "[" * 600 + "]" * 600)
def test_tolerance_loader_gives_usable_tolerances_or_one_clear_error(text):
    load_or_clear_error(text)


@pytest.mark.slow
@TOLERANCE_SLOW
@given(text=tolerance_text())
def test_tolerance_loader_fuzz_large(text):
    load_or_clear_error(text)


def test_the_bases_round_trip_through_the_writer():
    for document in BASES:
        assert tomllib.loads(toml_document(document)) == document
