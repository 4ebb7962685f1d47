"""Every ``--json`` output is strict JSON, and what an engine library prints never reaches stdout
(harness/common/jsonout.py, harness/common/capture.py, harness/cli.py,
harness/commands/output.py)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from mbh._harness import cli
from mbh._harness.commands.output import print_json
from mbh._harness.common import jsonout
from mbh._harness.common.capture import captured_output, engine_note
from tests.helpers import ROOT


def _refuse(token):
    raise ValueError(f"non-standard JSON token {token}")


def strict_loads(text: str):
    """json.loads that rejects NaN, Infinity and -Infinity."""
    return json.loads(text, parse_constant=_refuse)


def mbh(*argv: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "mbh._harness.cli", *argv], capture_output=True,
                          text=True, timeout=600, cwd=ROOT)


def test_non_finite_floats_are_written_as_strings():
    value = {"a": float("nan"), "b": [np.float64("inf"), -np.inf], "c": np.arange(2),
             "d": np.int64(3), "e": (1.5, None, True)}
    text = jsonout.dumps(value)
    assert strict_loads(text) == {"a": "NaN", "b": ["Infinity", "-Infinity"], "c": [0, 1],
                                  "d": 3, "e": [1.5, None, True]}
    assert [float(s) for s in strict_loads(text)["b"]] == [np.inf, -np.inf]


def test_an_object_json_cannot_hold_is_refused():
    with pytest.raises(TypeError, match="cannot write a set as JSON"):
        jsonout.dumps({"x": {1}})


def test_an_infinite_condition_number_comes_out_encoded(capsys):
    print_json({"scenario": "x", "jacobian_condition": float("inf")})
    assert strict_loads(capsys.readouterr().out)["jacobian_condition"] == "Infinity"


def test_capture_takes_what_c_code_prints_on_both_descriptors():
    import ctypes

    libc = ctypes.CDLL(None)
    with captured_output() as printed:
        libc.printf(b"from C on stdout\n")  # held in C's stdio buffer until the block flushes it
        os.write(2, b"raw on stderr\n")
    assert sorted(printed.text.splitlines()) == ["from C on stdout", "raw on stderr"]


def test_an_engine_note_is_trimmed():
    assert engine_note("  \n ") is None
    note = engine_note("x" * 5000, limit=100)
    assert note.startswith("the engine printed: " + "x" * 100) and "4900 more characters" in note


def test_simulate_ida_json_is_strict():
    result = mbh("simulate", "fourbar", "--adapter", "inhouse", "--method", "ida", "--dt", "1e-2",
                 "--t-end", "0.5", "--json")
    assert result.returncode == 0, result.stderr
    row = strict_loads(result.stdout)
    assert row["status"] == "ok" and row["samples"] == 51


def test_what_sundials_prints_goes_to_the_notes_not_stdout():
    # rtol = atol = 1e-20 makes IDA print "[IDASolve, Error: -22] ... too much accuracy requested"
    # with printf before it gives up (measured; scikit-sundae 1.1)
    result = mbh("simulate", "slider_crank_planar", "--method", "ida:rtol=1e-20,atol=1e-20",
                 "--dt", "1e-2", "--t-end", "0.5", "--json")
    assert result.returncode == 1, result.stderr  # the case failed
    row = strict_loads(result.stdout)
    assert row["status"] == "failed"
    assert any("too much accuracy requested" in note for note in row["notes"])
    assert "IDASolve" not in result.stderr


def test_check_all_json_is_strict():
    result = mbh("check", "--all", "--json")
    rows = strict_loads(result.stdout)
    assert {row["scenario"] for row in rows} >= {"fourbar", "slider_crank"}


@pytest.mark.parametrize("argv", [["scenarios", "--json"], ["methods", "--adapter", "mujoco",
                                                            "--json"]])
def test_listings_are_strict_json(capsys, argv):
    assert cli.main(argv) == 0
    strict_loads(capsys.readouterr().out)


#: Runs the command line with C-level writes to descriptor 1 (C's printf, buffered, and a raw
#: write) before and after the command's own work, as a solver or an engine makes them.
_NOISY_MAIN = """
import ctypes, os, sys
from mbh._harness import cli

libc = ctypes.CDLL(None)
real_parser = cli.build_parser


def noisy_parser():
    parser = real_parser()
    parse = parser.parse_args

    def parse_noisily(argv=None):
        args = parse(argv)
        command = args.func

        def noisy(namespace):
            libc.printf(b"[C printf before the command]\\n")
            os.write(1, b"[raw write before the command]\\n")
            status = command(namespace)
            libc.printf(b"[C printf after the command]\\n")
            return status

        args.func = noisy
        return args

    parser.parse_args = parse_noisily
    return parser


cli.build_parser = noisy_parser
sys.exit(cli.main(sys.argv[1:]))
"""


@pytest.mark.parametrize("argv", [
    ["simulate", "fourbar", "--adapter", "inhouse", "--method", "rk4+direct", "--dt", "1e-2",
     "--t-end", "0.2"],
    ["simulate", "slider_crank", "--adapter", "mujoco", "--method", "best", "--dt", "1e-3",
     "--t-end", "0.2"],
    ["check", "fourbar"],
    ["reference", "fourbar", "--quiet"],
    ["runs"],
])
def test_c_level_stdout_noise_never_reaches_the_json(argv, tmp_path):
    result = subprocess.run([sys.executable, "-c", _NOISY_MAIN, *argv, "--json"],
                            capture_output=True, text=True, timeout=600, cwd=ROOT,
                            env={**os.environ, "MBH_RESULTS_DIR": str(tmp_path)})
    assert result.returncode == 0, result.stderr
    strict_loads(result.stdout)
    for noise in ("[C printf before the command]", "[raw write before the command]",
                  "[C printf after the command]"):
        assert noise not in result.stdout
        assert noise in result.stderr
