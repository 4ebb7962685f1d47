"""Bad campaign files, tried by the thousand (issue 31 item 5): :func:`mbh._harness.run.spec.load_campaign`.

Every example is a shipped campaign mutated by Hypothesis — wrong types, NaN and ±inf, integers
beyond the double range, unknown scenarios, family members out of range, unknown adapters,
malformed method strings, steps that divide nothing, unknown keys, groups and sweeps replaced by
junk — sometimes with its TOML text broken too (cut, a 5000-digit integer, arrays nested 600
deep, bad UTF-8).  For every example the loader must return a campaign whose cases are all usable
or raise one :class:`CampaignError` whose problems each name the file, a field and the problem.

Profiles: the default suite tries :data:`DEFAULT_EXAMPLES` inputs, derandomized; the ``slow``
mark tries :data:`SLOW_EXAMPLES` with fresh randomness (the style of tests/model/test_fuzz.py).
"""

from __future__ import annotations

import copy
import math
import tomllib
from pathlib import Path

import pytest
from hypothesis import event, example, given, settings
from hypothesis import strategies as st

from mbh._adapters import adapter_names
from mbh._harness.model.scenario import scenario_names
from mbh._harness.run.spec import (Campaign, CampaignError, campaign_names, campaign_path,
                                   load_campaign)
from tests.fuzzing import BASE, BREAKS, HUGE, NAMES, NUMBERS, VALUES, fuzzed_file, toml_document

DEFAULT_EXAMPLES = 200
SLOW_EXAMPLES = 2000

CAMPAIGN_DEFAULT = settings(BASE, max_examples=DEFAULT_EXAMPLES)
CAMPAIGN_SLOW = settings(BASE, max_examples=SLOW_EXAMPLES, derandomize=False)

BASES = {name: tomllib.loads(campaign_path(name).read_text(encoding="utf-8"))
         for name in campaign_names()}

SCENES = st.sampled_from(scenario_names() + [
    "n_fourbar@3", "n_fourbar@0", "n_fourbar@257", "n_fourbar@03", "n_fourbar@x", "n_fourbar@",
    "n_fourbar@" + "9" * 5000, "nope@1", "@", "all", "*", "fourbar.toml", "../fourbar.toml",
    "/nonexistent/x.toml", "\x00.toml", "x" * 300 + ".toml", "FOURBAR", ""])
ADAPTERS = st.sampled_from(adapter_names() + ["", "all", "MuJoCo", "inhouse ", "*"])
METHODS = st.sampled_from([
    "best", "default", "rk4+direct", "rk4+direct:proj_tol=1e-12", "rk4+direct:proj_tol=nan",
    "rk4+direct:proj_tol=-1", "rk4+direct:proj_tol=1e999", "bdf4+direct:tol=1e-5", "best:x=1",
    "rk4+", "+", ":", "rk4+direct:=", "rk4+direct:a=1,a=2", "rk4+direct:,", "substeps:n=0",
    "substeps:n=1e400", "euler", "rk4", "newmark", "ida", ""])
VALID_STEPS = st.sampled_from([1e-2, 5e-3, 2e-3, 1e-3])
STEPS = st.one_of(VALID_STEPS, VALID_STEPS, st.sampled_from([1e-4, 3e-3, 0.02, 0.3]), NUMBERS,
                  HUGE)


def names(items, valid):
    """Mostly a short list of valid names, sometimes ``"all"``, junk names or anything."""
    return st.one_of(st.lists(valid, min_size=1, max_size=3), st.lists(valid, min_size=1,
                                                                       max_size=3),
                     st.just("all"), st.lists(items, min_size=0, max_size=4), VALUES)


SHIPPED_SCENES = st.sampled_from(["fourbar", "slider_crank", "n_fourbar@2"])
SHIPPED_ADAPTERS = st.sampled_from(adapter_names())


#: A value for each key a campaign file has, mostly of the right kind.
FIELD_VALUES = {
    "description": st.one_of(NAMES, VALUES),
    "repetitions": st.one_of(st.integers(1, 3), NUMBERS, HUGE, VALUES),
    "timeout_s": st.one_of(st.sampled_from([1.0, 60.0]), NUMBERS, HUGE, VALUES),
    "accuracy": st.one_of(st.sampled_from([1e-3, 1e-6]), NUMBERS, HUGE, VALUES),
    "calibration": st.one_of(st.booleans(), VALUES),
    "bounds": st.one_of(st.dictionaries(st.sampled_from(["gap", "orientation", "energy",
                                                         "branch", "trajectory", "nope"]),
                                        st.one_of(NUMBERS, HUGE), max_size=3), VALUES),
    "t_end": st.one_of(st.dictionaries(st.one_of(SCENES, st.just("*")),
                                       st.one_of(NUMBERS, HUGE, STEPS), max_size=3), VALUES),
    "scenarios": names(SCENES, SHIPPED_SCENES), "except": names(SCENES, SHIPPED_SCENES),
    "adapters": names(ADAPTERS, SHIPPED_ADAPTERS),
    "methods": st.one_of(st.lists(st.sampled_from(["best", "default"]), min_size=1, max_size=2),
                         st.lists(METHODS, max_size=3),
                         st.dictionaries(ADAPTERS, st.one_of(st.lists(METHODS, max_size=3),
                                                             VALUES), max_size=3), VALUES),
    "dts": st.one_of(st.lists(VALID_STEPS, min_size=1, max_size=2), st.lists(STEPS, max_size=3),
                     VALUES),
    "dt_min": STEPS, "dt_max": STEPS, "max_bisections": st.one_of(NUMBERS, HUGE, VALUES),
    "group": VALUES, "sweep": VALUES, "unknown": VALUES,
}
KEYS = st.sampled_from(sorted(FIELD_VALUES))


def tables(document: dict) -> list[dict]:
    """The document and each of its group, sweep and t_end tables."""
    found = [document]
    if isinstance(document.get("group"), list):
        found += [group for group in document["group"] if isinstance(group, dict)]
    found += [document[key] for key in ("sweep", "t_end") if isinstance(document.get(key), dict)]
    found += [g["t_end"] for g in found[1:] if isinstance(g.get("t_end"), dict)]
    return found


MUTATIONS = ["set"] * 6 + ["delete"] * 2 + ["duplicate", "drop_groups", "retype"]


@st.composite
def mutated(draw) -> dict:
    """A shipped campaign with one to four mutations (every drawn value deep-copied in: see
    tests/model/test_fuzz.py, ``mutated``)."""
    document = copy.deepcopy(BASES[draw(st.sampled_from(sorted(BASES)))])
    for _ in range(draw(st.sampled_from([1, 1, 1, 2, 3]))):
        kind = draw(st.sampled_from(MUTATIONS))
        table = draw(st.sampled_from(tables(document)))
        if kind == "set":
            own = table and draw(st.integers(0, 3)) > 0
            key = draw(st.sampled_from(sorted(table)) if own else KEYS)
            table[key] = copy.deepcopy(draw(FIELD_VALUES.get(key, VALUES)))
        elif kind == "delete" and table:
            del table[draw(st.sampled_from(sorted(table)))]
        elif kind == "duplicate" and isinstance(document.get("group"), list):
            document["group"] = document["group"] + copy.deepcopy(document["group"])
        elif kind == "drop_groups":
            document.pop("group", None)
        elif kind == "retype" and table:
            key = draw(st.sampled_from(sorted(table)))
            table[key] = copy.deepcopy(draw(VALUES))
    return document


#: Text breakage: TOML syntax, bad UTF-8, an integer tomllib refuses to convert, arrays nested
#: deeper than tomllib can recurse.


@st.composite
def campaign_text(draw) -> str:
    """A mutated campaign's TOML; sometimes with its text broken too."""
    document = draw(mutated())
    try:
        text = toml_document(document)
    except ValueError:  # str() refuses an integer of over 4300 digits
        text = "x = 1\n"
    for _ in range(draw(st.sampled_from([0, 0, 0, 0, 1, 2]))):
        at = draw(st.integers(0, len(text)))
        text = text[:at] + draw(BREAKS) + text[at + draw(st.integers(0, 5)):]
    return text


# -- the oracle ----------------------------------------------------------------------------------
def assert_usable(loaded: Campaign) -> None:
    """Every case and the sweep hold numbers a run can use."""
    for case in loaded.cases:
        assert math.isfinite(case.dt) and case.dt > 0, case
        assert math.isfinite(case.t_end) and case.t_end >= case.dt, case
        assert isinstance(case.repetitions, int) and case.repetitions >= 1, case
        assert math.isfinite(case.timeout_s) and case.timeout_s > 0, case
    assert math.isfinite(loaded.accuracy) and loaded.accuracy > 0
    if loaded.sweep is not None:
        assert 0 < loaded.sweep.dt_min < loaded.sweep.dt_max < math.inf


def load_or_clear_error(text: str) -> None:
    with fuzzed_file(text) as path:
        try:
            loaded = load_campaign(path)
        except CampaignError as error:
            assert error.problems, "a CampaignError without problems"
            for problem in error.problems:
                assert problem.file == str(path), problem
                assert problem.field and problem.message, problem
            assert str(error).startswith(f"{path}: ")
            event("campaign: rejected")
            return
    assert_usable(loaded)
    event(f"campaign: loaded ({'no cases' if not loaded.cases else 'cases'})")


def with_value(key: str, value) -> str:
    document = copy.deepcopy(BASES["smoke"])
    document[key] = value
    return toml_document(document)


@CAMPAIGN_DEFAULT
@given(text=campaign_text())
# Found: an integer beyond the double range raised OverflowError (math.isfinite, float()).
@example(text=with_value("timeout_s", 10**400))
@example(text=toml_document({"group": [{"scenarios": ["fourbar"], "adapters": ["inhouse"],
                                        "methods": ["best"], "dts": [10**400]}]}))
# Found: tomllib raised ValueError for a 5000-digit integer and RecursionError for deep arrays.
@example(text="x = " + "9" * 5000)
@example(text="x = " + "[" * 600 + "]" * 600)
# Found: a family member with a 5000-digit parameter raised ValueError.
@example(text=toml_document({"group": [{"scenarios": ["n_fourbar@" + "9" * 5000],
                                        "adapters": ["inhouse"], "methods": ["best"],
                                        "dts": [1e-2]}]}))
# Found: a step of 1e-308 s divides 0.01 s in doubles, but duration / dt overflowed round().
@example(text=toml_document({"group": [{"scenarios": ["fourbar"], "adapters": ["inhouse"],
                                        "methods": ["best"], "dts": [1e-308]}]}))
# Found (slow profile): a scenario file name with a NUL raised ValueError in Path.resolve().
@example(text=toml_document({"group": [{"scenarios": ["\x00.toml"], "adapters": ["inhouse"],
                                        "methods": ["best"], "dts": [1e-2]}]}))
def test_campaign_loader_gives_usable_cases_or_one_clear_error(text):
    load_or_clear_error(text)


@pytest.mark.slow
@CAMPAIGN_SLOW
@given(text=campaign_text())
def test_campaign_loader_fuzz_large(text):
    load_or_clear_error(text)


def test_every_shipped_campaign_round_trips_through_the_writer():
    """The mutations start from the shipped files as they parse (the writer loses nothing)."""
    for name, document in BASES.items():
        assert tomllib.loads(toml_document(document)) == document, name


def test_a_campaign_file_that_is_a_folder_is_a_clear_error(tmp_path):
    folder = tmp_path / "folder.toml"
    folder.mkdir()
    with pytest.raises(CampaignError, match=r"folder\.toml: -: cannot read the file"):
        load_campaign(Path(folder))
