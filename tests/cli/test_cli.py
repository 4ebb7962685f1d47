"""The `mbh` command line: JSON contract of `simulate`, listings, and user errors (the exit
statuses themselves: tests/cli/test_exit_status.py)."""

from __future__ import annotations

import json

import pytest

from mbh._harness import cli

REQUIRED = {"status", "reason", "failure_time", "wall_time_s", "steps", "rhs_evals", "outputs",
            "max_constraint_violation", "max_velocity_violation", "max_energy_error_J",
            "output_errors"}


def run_json(capsys, *argv):
    status = cli.main([*argv, "--json"])
    return status, json.loads(capsys.readouterr().out)


@pytest.mark.parametrize("adapter", ["inhouse", "mujoco", "pybullet", "pinocchio", "exudyn"])
def test_simulate_json_holds_the_harness_metrics(capsys, adapter):
    status, result = run_json(capsys, "simulate", "fourbar", "--adapter", adapter,
                              "--method", "best", "--dt", "0.01", "--t-end", "0.5",
                              "--accuracy", "0.1")
    assert status == 0
    assert REQUIRED <= set(result) and result["accurate"] is True
    assert result["status"] == "ok" and result["steps"] == 50
    assert set(result["outputs"]) == {"crank_angle", "crank_rate"}
    assert result["output_errors"]["crank_angle"] < 0.1


def test_simulate_reports_a_blow_up_as_a_status(capsys):
    status, result = run_json(capsys, "simulate", "slider_crank_planar", "--method", "euler+none",
                              "--dt", "0.01")
    assert status == 1
    assert result["status"] == "diverged" and 0 < result["failure_time"] <= 4.0


def test_check_json_lists_every_scenario(capsys):
    status, rows = run_json(capsys, "check", "--all")
    assert status == 0
    assert {r["scenario"] for r in rows} >= {"fourbar", "fourbar_spatial", "slider_crank",
                                             "slider_crank_planar"}
    for row in rows:
        assert {"n_bodies", "n_coordinates", "n_equations", "rank", "mobility", "grubler_mobility",
                "redundant_equations", "assembly_residual", "jacobian_condition"} <= set(row)


@pytest.mark.parametrize("argv,message", [
    (["methods", "--adapter", "ode"], "unknown adapter 'ode'; valid: inhouse"),
    (["simulate", "fourbar", "--method", "rk4+nope", "--dt", "0.01"],
     "mbh: method: unknown stabilisation"),
    (["simulate", "fourbar", "--dt", "-1"], "mbh: dt: expected a finite step > 0 (s), got -1.0"),
    (["simulate", "nosuch", "--dt", "0.01"], "no such scenario file"),
    (["simulate", "fourbar", "--dt", "0.00123456789"],
     "mbh: dt: step dt = 0.00123457 s does not divide the evaluation grid step 0.01 s"),
    (["simulate", "fourbar", "--dt", "nan"], "mbh: dt: expected a finite step > 0 (s), got nan"),
    (["simulate", "fourbar", "--dt", "0.01", "--t-end", "9"],
     "mbh: t_end: expected a time in (0, 4.0] s, got 9.0"),
    (["simulate", "fourbar", "--dt", "1e-300"], "steps to 4 s (at most 1e+08)"),
    (["simulate", "fourbar", "--dt", "0.01", "--bounds", "gap=0"],
     "--bounds: bounds: gap must be a positive finite number"),
    (["simulate", "fourbar", "--dt", "0.01", "--bounds", "size=1"], "NAME one of gap, "),
])
def test_user_errors_exit_2_without_traceback(capsys, argv, message):
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def test_simulate_reports_the_sticks_verdict(capsys):
    # the in-house default at dt 1e-2 on the planar slider-crank: its own integrator finishes, the
    # stick fails it.  Measured: from 3.08 s its crank is more than 0.1 rad from the reference's
    # at the same time (1.05 rad at 3.93 s, while its points stay within 0.508 m, 24 % of the
    # size); from 3.37 s its joints are open by more than 0.5 % of the size (1.6 % at most)
    status, result = run_json(capsys, "simulate", "slider_crank_planar", "--dt", "0.01")
    assert status == 1
    assert result["status"] == "failed"
    assert result["reason"].startswith("at t = 3.08 s: left the reference's motion (body crank "
                                       "is turned ")
    _, turn_allowed = run_json(capsys, "simulate", "slider_crank_planar", "--dt", "0.01",
                               "--bounds", "trajectory=1.1")
    assert turn_allowed["status"] == "failed"
    assert turn_allowed["reason"].startswith("at t = 3.37 s: joint gap ")
    _, loose = run_json(capsys, "simulate", "slider_crank_planar", "--dt", "0.01", "--bounds",
                        "gap=0.05,energy=0.5,trajectory=1.1")
    assert loose["status"] == "ok"


def test_methods_lists_default_and_best_for_every_adapter(capsys):
    for adapter in ("inhouse", "mujoco", "pybullet", "pinocchio", "exudyn"):
        _, rows = run_json(capsys, "methods", "--adapter", adapter)
        assert {"default", "best"} <= {r["method"] for r in rows}


def test_scenarios_with_no_scenario_files_says_where_it_looked(capsys, monkeypatch, tmp_path):
    # As in an installed package that ships no scenario files: a header, no traceback.
    from mbh._harness.model import scenario

    monkeypatch.setattr(scenario, "SCENARIO_DIR", tmp_path)
    assert cli.main(["scenarios"]) == 0
    out, err = capsys.readouterr()
    assert out.split() == ["name", "kind", "bodies", "joints", "tags"]
    assert f"no scenario files in {tmp_path}" in err


def test_reference_names_its_independent_route_and_agreement(capsys):
    """The shipped four-bar's reference: route A against the neutral full route (no contestant's
    code), 1.5e-11 rad apart as stored; the command reports it, within the 1e-9 limit."""
    status, result = run_json(capsys, "reference", "fourbar", "--quiet")
    assert status == 0
    assert result["independent_route"] == "neutral-full:dop853"
    assert 0.0 < result["independent_agreement"] <= 1e-9
