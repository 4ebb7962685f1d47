"""The vocabulary the fuzz tests share (tests/model/test_fuzz.py: the scenario loader and the
CLI; tests/model/test_fuzz_builder.py: the Python builder; tests/run/test_fuzz_campaigns.py:
campaign files; tests/testing/test_fuzz_tolerances.py: tolerance files): the settings every
profile starts from, a TOML writer, evil values, the shipped scenario documents, and the oracles
that judge a loaded mechanism."""

from __future__ import annotations

import contextlib
import json
import math
import re
import tempfile
import tomllib
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

from mbh._harness.model import scenario
from mbh._harness.model.mechanism import Mechanism

#: What every fuzz profile starts from (each sets its own ``max_examples``; the slow ones draw
#: fresh randomness with ``derandomize=False``).
BASE = settings(derandomize=True, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])

#: The shipped scenarios' documents, by name: what the mutations start from.
SCENARIO_DOCUMENTS = {name: tomllib.loads(scenario.scenario_path(name).read_text(encoding="utf-8"))
                      for name in scenario.scenario_names()}

# -- a tiny TOML writer (no dependency): every value inline, every table an inline table --------
_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")


def toml_string(text: str) -> str:
    """A TOML basic string: JSON's escapes are TOML's, except that TOML also escapes DEL."""
    return json.dumps(text, ensure_ascii=False).replace("\x7f", "\\u007f")


def toml_key(key: str) -> str:
    return key if _BARE_KEY.match(key) else toml_string(key)


def toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return toml_string(value)
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{toml_key(k)} = {toml_value(v)}" for k, v in value.items()) + "}"
    raise TypeError(f"no TOML for {type(value).__name__}")


def toml_document(document: dict) -> str:
    return "".join(f"{toml_key(k)} = {toml_value(v)}\n" for k, v in document.items())



# -- evil values --------------------------------------------------------------------------------
NAMES = st.sampled_from([
    "", " ", "ground", "<script>alert(1)</script>", "\u202eevil\u202c", "crank\u200b", "🦀", "名前",
    "a\nb", "a\"b", "x" * 300, "\x00", "\x7f", "𝔠𝔯𝔞𝔫𝔨", "../../etc/passwd", "${HOME}", "%s%n",
])
NUMBERS = st.sampled_from([
    math.nan, math.inf, -math.inf, 0, 0.0, -0.0, 1e308, -1e308, 1e-308, 5e-324, 1e-300, 1e300,
    -1.0, 1, 2**63 - 1, -(2**63), 1e-12, 1e12,
])
VECTORS = st.one_of(
    st.lists(NUMBERS, min_size=3, max_size=3),
    st.sampled_from([[0.0, 0.0, 0.0], [1e-300, 0.0, 0.0], [1e308, 1e308, 0.0],
                     [1e200, 1e200, 1e200],
                     [], [1.0], [1.0, 2.0], [1.0, 2.0, 3.0, 4.0], [[1.0], [2.0], [3.0]],
                     [1.0, "2", 3.0], [True, False, True], [1, 0, 0], [0.0, 0.0, 1.0],
                     [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]]),
)
VALUES = st.one_of(NUMBERS, NAMES, VECTORS, st.booleans(),
                   st.sampled_from([{}, {"a": 1}, [{}], [{"name": "x"}], "revolute", "spherical",
                                    "universal", "prismatic", "x", "y", "z", "w"]))
#: Keys of scenario tables, and some that are not.
SCENARIO_KEYS = st.sampled_from([
    "name", "kind", "plane", "duration", "gravity", "mass", "inertia", "position", "angle_deg",
    "euler313_deg", "quaternion", "type", "body1", "body2", "location", "location2", "axis",
    "axis2", "normal", "joint", "value", "rate", "driver", "guess", "velocities", "body",
    "velocity", "components", "component", "force", "point", "torque", "stiffness", "damping",
    "free_length", "location1", "outputs", "initial", "bodies", "joints", "forces", "unknown",
])


#: Integers TOML reads but no double holds, and the largest a double holds.
HUGE = st.sampled_from([10**400, -(10**400), 2**1024, 2**1023])
#: What breaks a TOML text when spliced into it.
BREAKS = st.sampled_from(["", "=", "[", "]", "{", '"', "\n", "\\", "\x00", "\ud800", "é",
                          "[[group]]\n", "\nx = " + "9" * 5000 + "\n",
                          "\nx = " + "[" * 600 + "]" * 600 + "\n"])


# -- the oracles ---------------------------------------------------------------------------------
@contextlib.contextmanager
def fuzzed_file(text: str):
    """The text in ``<fresh tmp dir>/fuzzed.toml``, removed afterwards (Hypothesis examples cannot
    share pytest's function-scoped tmp_path)."""
    with tempfile.TemporaryDirectory(prefix="mbh-fuzz-") as folder:
        path = Path(folder) / "fuzzed.toml"
        path.write_bytes(text.encode("utf-8", errors="surrogatepass"))  # lone surrogates: bad UTF-8
        yield path


def finite_numbers(value) -> bool:
    """True when every number inside ``value`` (dataclasses, arrays, containers) is finite."""
    if isinstance(value, np.ndarray):
        return bool(np.all(np.isfinite(value)))
    if isinstance(value, float):
        return math.isfinite(value)
    if isinstance(value, (list, tuple)):
        return all(finite_numbers(v) for v in value)
    if isinstance(value, dict):
        return all(finite_numbers(v) for v in value.values())
    if hasattr(value, "__dataclass_fields__"):
        return all(finite_numbers(getattr(value, f)) for f in value.__dataclass_fields__)
    return True


def assert_clean_mechanism(mech: Mechanism) -> None:
    """All numbers finite, masses positive, rotations orthonormal, joint directions unit.

    The 1e-12 bounds hold round-off of one normalisation or rotation product (~1e-16) with room.
    """
    assert finite_numbers(mech), "a loaded mechanism holds a non-finite number"
    for body in mech.bodies:
        assert body.mass > 0
        assert np.allclose(body.rotation.T @ body.rotation, np.eye(3), atol=1e-12)
    for joint in mech.joints:
        for axis in (joint.axis1, joint.axis2, joint.normal1, joint.normal2):
            assert abs(np.linalg.norm(axis) - 1.0) < 1e-12, f"joint {joint.name}: axis not unit"
