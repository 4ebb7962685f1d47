"""``mbh warm-up`` (harness/run/warm_up.py): its phases run in parallel processes, idle processes
take the cases beside the phases and the fill cases, and a case that fails is reported, not
raised."""

from __future__ import annotations

import json

from mbh._harness import cli
from mbh._harness.run import warm_up


def test_every_case_runs_once_and_a_failure_is_a_row(monkeypatch, capsys):
    monkeypatch.setattr(warm_up, "PHASES", (
        (("fourbar", "rk4+direct:loop=generated", 1e-3, 0.002, "a generated loop"),
         ("fourbar", "rk4+nosuch", 1e-3, 0.002, "a method that does not exist")),
        (("simple_pendulum", "rk4+baumgarte:loop=compiled", 1e-3, 0.002, "a kernels' loop"),),
    ))
    monkeypatch.setattr(warm_up, "BESIDE_PHASES", (
        ("simple_pendulum", "rk4+baumgarte:loop=python", 1e-3, 0.002, "a Python-path case"),))
    monkeypatch.setattr(warm_up, "FILL_SCENES", ("simple_pendulum",))
    monkeypatch.setattr(warm_up, "NEUTRAL_FILL_SCENES", ())
    assert cli.main(["warm-up", "--jobs", "2", "--json", "--quiet"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert sorted((row["scenario"], row["method"]) for row in rows) == [
        ("fourbar", "rk4+direct:loop=generated"), ("fourbar", "rk4+nosuch"),
        ("simple_pendulum", "rk4+baumgarte:loop=compiled"),
        ("simple_pendulum", "rk4+baumgarte:loop=generated"),
        ("simple_pendulum", "rk4+baumgarte:loop=python"),
        ("simple_pendulum", "rk4+direct:loop=generated")]
    problems = {row["method"]: row["problem"] for row in rows if row["problem"]}
    assert list(problems) == ["rk4+nosuch"] and "unknown stabilisation" in problems["rk4+nosuch"]
    phase_two = [row["method"] for row in rows].index("rk4+baumgarte:loop=compiled")
    phase_one = [i for i, row in enumerate(rows) if row["scenario"] == "fourbar"]
    assert max(phase_one) < phase_two, "a phase starts after the previous one has ended"
