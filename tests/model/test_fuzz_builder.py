"""The Python mechanism builder, called with junk by the thousand (issue 31 item 5):
:class:`mbh._harness.model.builder.MechanismBuilder`.

Every example types a shipped scenario as builder calls (as tests/model/test_builder.py does),
then Hypothesis changes them — random section calls (``body``, ``joint``, ``force``,
``initial``, ``output``, ``reference``, top-level fields) with random field names and values of
every Python type: numpy arrays of every dtype and shape, numpy scalars, NaN, ±inf, integers
beyond 64 bits and beyond the double range, tuples, sets, bytes, complex numbers, None, objects,
generators, dicts with keys that are not strings, lists nested 100 deep or holding themselves.
For every example :meth:`~MechanismBuilder.build` must return a mechanism whose numbers are all
finite, or raise one :class:`ScenarioError` whose problems each name ``<python: NAME>``, a field
and the problem.

Profiles: the default suite tries :data:`DEFAULT_EXAMPLES` inputs, derandomized; the ``slow``
mark tries :data:`SLOW_EXAMPLES` with fresh randomness (the style of tests/model/test_fuzz.py).
"""

from __future__ import annotations

import copy
import datetime

import numpy as np
import pytest
from hypothesis import event, example, given, settings
from hypothesis import strategies as st

from mbh._harness.model.builder import MAX_DEPTH, MechanismBuilder
from mbh._harness.model.scenario import ScenarioError
from tests.fuzzing import (BASE, NAMES, NUMBERS, SCENARIO_DOCUMENTS, SCENARIO_KEYS, VALUES,
                           VECTORS, assert_clean_mechanism)

DEFAULT_EXAMPLES = 300
SLOW_EXAMPLES = 3000

BUILDER_DEFAULT = settings(BASE, max_examples=DEFAULT_EXAMPLES)
BUILDER_SLOW = settings(BASE, max_examples=SLOW_EXAMPLES, derandomize=False)

SECTIONS = ("body", "joint", "force", "initial", "output", "reference")


def calls_of(document: dict) -> list[list]:
    """The builder calls that make ``document``: ``[method, positional args, fields]``, the
    constructor first (``["init", [name], top-level fields]``)."""
    top = {k: v for k, v in document.items()
           if k not in ("bodies", "joints", "forces", "initial", "outputs", "reference")}
    calls = [["init", ["fuzzed"], top]]
    for body in document.get("bodies", []):
        fields = dict(body)
        calls.append(["body", [fields.pop("name", "b")], fields])
    for joint in document.get("joints", []):
        fields = dict(joint)
        calls.append(["joint", [fields.pop("name", "j"), fields.pop("type", "revolute")], fields])
    for force in document.get("forces", []):
        fields = dict(force)
        calls.append(["force", [fields.pop("type", "joint_torque")], fields])
    if "initial" in document:
        calls.append(["initial", [], dict(document["initial"])])
    for name, output in document.get("outputs", {}).items():
        fields = dict(output)
        calls.append(["output", [name, fields.pop("kind", "joint_angle")], fields])
    if "reference" in document:
        calls.append(["reference", [], dict(document["reference"])])
    return calls


#: Each call's positional parameters: a field of the same name would be Python's own TypeError
#: ("got multiple values for argument"), not the builder's, so the calls leave such fields out.
POSITIONAL = {"init": ("name",), "body": ("name",), "joint": ("name", "type"),
              "force": ("type",), "output": ("name", "kind"), "initial": (), "reference": ()}


def make(calls: list[list]) -> MechanismBuilder:
    """Run the calls (``make(calls_of(document))`` builds ``document``)."""
    builder = None
    for method, args, fields in calls:
        fields = {k: v for k, v in fields.items() if k not in POSITIONAL[method]}
        if method == "init":
            builder = MechanismBuilder(*args, **fields)
        else:
            getattr(builder, method)(*args, **fields)
    return builder


# -- Python junk: made fresh per example (a drawn object is never shared between examples) -------
def self_holding() -> list:
    items: list = [1.0, 2.0]
    items.append(items)
    return items


def nested(depth: int):
    value: object = [0.0, 0.0, 0.0]
    for _ in range(depth):
        value = [value]
    return value


JUNK_MAKERS = {
    "huge int": lambda: 10**400, "int beyond 64 bits": lambda: 2**64, "int -2^63": lambda: -(2**63),
    "5000-digit int": lambda: 10**5000, "complex": lambda: 1 + 2j, "None": lambda: None,
    "bytes": lambda: b"\xff\x00", "set": lambda: {1.0, 2.0, 3.0}, "frozenset": lambda: frozenset(),
    "object": object, "generator": lambda: (x for x in range(3)),
    "function": lambda: (lambda: 1), "datetime": lambda: datetime.datetime(2026, 1, 1),
    "tuple": lambda: (1.0, 0.0, 0.0), "nested 100": lambda: nested(100),
    "nested to the limit": lambda: nested(MAX_DEPTH - 2), "self-holding list": self_holding,
    "int keys": lambda: {1: 2.0, "x": 1.0}, "tuple key": lambda: {(1, 2): [0.0]},
    "nested int key": lambda: [{"a": {3: 4}}], "range": lambda: range(3),
    "float subclass": lambda: np.float64(1.5), "float128": lambda: np.longdouble(1.0),
    "numpy int": lambda: np.int64(7), "numpy uint max": lambda: np.uint64(2**64 - 1),
    "numpy bool": lambda: np.bool_(True), "numpy str": lambda: np.str_("x"),
    "numpy nan": lambda: np.float32("nan"), "numpy datetime": lambda: np.datetime64("2026-01-01"),
}
ARRAY_DTYPES = ["float64", "float32", "float16", "int64", "int8", "uint64", "bool", "complex128",
                "object", "U3"]
ARRAY_SHAPES = [(3,), (4,), (6,), (2,), (0,), (1, 3), (3, 1), (3, 3), (), (2, 2, 2)]
ARRAY_FILL = [0.0, 1.0, -1.0, 0.5, np.nan, np.inf, -np.inf, 1e308, 1e-320, 2.0**70]


def array(dtype: str, shape: tuple, fill: list) -> np.ndarray:
    """An array of ``dtype`` and ``shape`` filled cyclically from ``fill`` (values the dtype
    cannot hold become its zero)."""
    size = int(np.prod(shape))
    values = [fill[i % len(fill)] for i in range(size)]
    with np.errstate(all="ignore"):
        try:
            return np.array(values, dtype=dtype).reshape(shape)
        except (ValueError, OverflowError, TypeError):
            return np.zeros(shape, dtype=dtype)


ARRAYS = st.builds(array, st.sampled_from(ARRAY_DTYPES), st.sampled_from(ARRAY_SHAPES),
                   st.lists(st.sampled_from(ARRAY_FILL), min_size=1, max_size=4))
#: A made value: a junk maker's name, or an array recipe (strategies draw recipes, the test makes
#: the objects, so no object is shared between examples).
RECIPES = st.one_of(st.sampled_from(sorted(JUNK_MAKERS)).map(lambda name: ("junk", name)),
                    st.tuples(st.sampled_from(ARRAY_DTYPES), st.sampled_from(ARRAY_SHAPES),
                              st.lists(st.sampled_from(ARRAY_FILL), min_size=1, max_size=4))
                    .map(lambda recipe: ("array", recipe)))
PYTHON_VALUES = st.one_of(NUMBERS, NAMES, VECTORS, VALUES, RECIPES, RECIPES,
                          VECTORS.map(lambda v: ("as array", v)))


def realised(value):
    """``value`` with recipes made into objects."""
    if isinstance(value, tuple) and len(value) == 2 and value[0] == "junk":
        return JUNK_MAKERS[value[1]]()
    if isinstance(value, tuple) and len(value) == 2 and value[0] == "array":
        return array(*value[1])
    if isinstance(value, tuple) and len(value) == 2 and value[0] == "as array":
        try:
            return np.asarray(value[1])
        except ValueError:  # ragged
            return np.asarray(value[1], dtype=object)
    return copy.deepcopy(value)


MUTATIONS = ["set"] * 6 + ["arrays"] * 2 + ["call"] * 2 + ["delete", "drop", "rename", "name"]


@st.composite
def builder_calls(draw) -> list[list]:
    """A shipped scenario as builder calls, with one to four mutations."""
    calls = calls_of(copy.deepcopy(SCENARIO_DOCUMENTS[draw(st.sampled_from(sorted(SCENARIO_DOCUMENTS)))]))
    for _ in range(draw(st.sampled_from([1, 1, 2, 3, 4]))):
        kind = draw(st.sampled_from(MUTATIONS))
        call = draw(st.sampled_from(calls))
        fields = call[2]
        if kind == "set":
            own = fields and draw(st.integers(0, 3)) > 0
            key = draw(st.sampled_from(sorted(fields)) if own else SCENARIO_KEYS)
            fields[key] = realised(draw(PYTHON_VALUES))
        elif kind == "arrays":  # every list of numbers of the call as a numpy array
            dtype = draw(st.sampled_from(["float64", "float32", "int64", "object"]))
            for key, value in fields.items():
                if isinstance(value, list) and all(isinstance(v, (int, float)) for v in value):
                    with np.errstate(all="ignore"):
                        try:
                            fields[key] = np.asarray(value, dtype=dtype)
                        except (OverflowError, ValueError):  # no int64 holds it: big, inf or NaN
                            fields[key] = np.asarray(value, dtype=object)
        elif kind == "call":  # a new section call with random arguments
            method = draw(st.sampled_from(SECTIONS))
            arity = {"body": 1, "joint": 2, "force": 1, "output": 2}.get(method, 0)
            args = [realised(draw(st.one_of(NAMES, PYTHON_VALUES))) for _ in range(arity)]
            extra = draw(st.dictionaries(SCENARIO_KEYS, PYTHON_VALUES, max_size=4))
            calls.append([method, args, {k: realised(v) for k, v in extra.items()}])
        elif kind == "delete" and fields:
            del fields[draw(st.sampled_from(sorted(fields)))]
        elif kind == "drop" and call[0] != "init":
            calls = [c for c in calls if c is not call]
        elif kind == "rename" and call[1]:  # a junk name or type
            call[1][draw(st.integers(0, len(call[1]) - 1))] = realised(draw(PYTHON_VALUES))
        elif kind == "name":
            calls[0][1] = [realised(draw(st.one_of(NAMES, PYTHON_VALUES)))]
    return calls


# -- the oracle ----------------------------------------------------------------------------------
def build_or_clear_error(calls: list[list]) -> None:
    builder = make(calls)
    source = builder.source
    try:
        mechanism = builder.build()
    except ScenarioError as error:
        assert error.problems, "a ScenarioError without problems"
        for problem in error.problems:
            assert problem.file == source, problem
            assert problem.field and problem.message, problem
        assert str(error).startswith(f"{source}: ")
        event("builder: rejected")
        return
    assert_clean_mechanism(mechanism)
    event("builder: built")


def fourbar_with(method: str, args: list, fields: dict) -> list[list]:
    return calls_of(copy.deepcopy(SCENARIO_DOCUMENTS["fourbar"])) + [[method, args, fields]]


@BUILDER_DEFAULT
@given(calls=builder_calls())
# Found: an integer beyond the double range raised OverflowError (math.isfinite, np.asarray).
@example(calls=fourbar_with("body", ["extra"], {"mass": 10**400, "inertia": [1, 1, 1],
                                                 "position": [0.0, 0.0, 0.0]}))
# Found: an output named by a non-string raised TypeError (iterating the name).
@example(calls=fourbar_with("output", [5, "joint_angle"], {"joint": "R"}))
# Found: a value deepcopy cannot copy (a generator) raised TypeError in document().
@example(calls=fourbar_with("reference", [], {"routes": (x for x in range(3))}))
# Found: a list holding itself raised RecursionError.
@example(calls=fourbar_with("initial", [], {"driver": self_holding()}))
# Found (slow profile): angle_deg=None (no file can say it) was taken as "not given" by the
# collector's typed readers, so a body was dropped without a problem and build() returned a
# mechanism holding None for it.
@example(calls=fourbar_with("body", ["extra"], {"mass": 1.0, "inertia": [1.0, 1.0, 1.0],
                                                 "position": [0.0, 0.0, 0.0], "angle_deg": None}))
# Found (slow profile): a name of 5000 digits raised ValueError (str() of the int) for the
# source "<python: NAME>".
@example(calls=[["init", [10**5000], {}]])
# Found: MechanismBuilder(None) was reported as "name: missing required field".
@example(calls=[["init", [None], {}]])
def test_builder_gives_a_clean_mechanism_or_one_clear_error(calls):
    build_or_clear_error(calls)


@pytest.mark.slow
@BUILDER_SLOW
@given(calls=builder_calls())
def test_builder_fuzz_large(calls):
    build_or_clear_error(calls)


def test_the_calls_rebuild_every_shipped_scenario():
    for name, document in SCENARIO_DOCUMENTS.items():
        built = make(calls_of(copy.deepcopy(document))).document()
        assert built == {k: v for k, v in document.items() if k != "name"}, name


def test_what_no_file_can_hold_is_named_with_its_field():
    builder = make(fourbar_with("body", ["extra"], {"mass": 2**64, "inertia": {1: 2},
                                                     "position": nested(MAX_DEPTH + 1)}))
    with pytest.raises(ScenarioError) as raised:
        builder.build()
    fields = [problem.field for problem in raised.value.problems]
    assert fields[:2] == ["bodies[3].mass", "bodies[3].inertia"], fields
    assert len(fields) == 3 and fields[2].startswith("bodies[3].position[0][0]"), fields


def test_a_huge_integer_in_a_scenario_file_is_a_clear_error(tmp_path):
    """The file loader's side of the first finding (both read through the same collector)."""
    from mbh._harness.model import scenario

    path = tmp_path / "huge.toml"
    path.write_text("duration = 1" + "0" * 400 + "\n")
    with pytest.raises(ScenarioError, match=r"huge\.toml: duration: expected a finite number"):
        scenario.load(path)
