"""Stability sweep: the largest step that still gives a trustworthy, accurate run.

For each (scenario, adapter, method) of a campaign's ``[sweep]`` the sweep bisects on the step
size dt over the admissible steps between the campaign's ``dt_min`` and ``dt_max``: the steps
that divide the scene's evaluation grid step, dt = 0.01 s / k for an integer k (or the scene's
finer ``sample_step`` / k, :mod:`mbh._harness.model.timegrid`).
A step passes when its run ends ``ok`` and, where the scenario has a verified reference, its
main-output error is within the campaign's accuracy threshold (the row's ``accurate``); without a
reference only the status counts, and the row's ``criterion`` says so.

The search assumes that passing is monotone in dt (every step below a passing one passes).  It
tries ``dt_max`` first (passing: done), then ``dt_min`` (failing: no step passes), then bisects
geometrically in k between the largest failing and the smallest passing step, at most
``max_bisections`` times, so the answer is exact when the bracket closes (neighbouring k) and
otherwise a passing step within the final bracket.  All (scenario, adapter, method) searches
advance together, one batch of cases per round, through the campaign's executor.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

from mbh._harness.common.jsonout import dumps
from mbh._harness.common.status import CaseStatus
from mbh._harness.model.timegrid import EVALUATION_STEP


def passes(row: dict) -> bool:
    """Whether a sweep run counts as stable: ``ok`` and not known to be inaccurate."""
    return row.get("status") == CaseStatus.OK and row.get("accurate") is not False


@dataclass
class Bisection:
    """The search of one (scenario, adapter, method) over k (dt = base / k).

    Attributes
    ----------
    k_min, k_max : int
        Bounds of k: k_min gives the largest step (dt_max), k_max the smallest (dt_min).
    k_fail : int or None
        Largest k known to fail (None: none known).
    k_pass : int or None
        Smallest k known to pass (None: none known).
    tried : list of [dt, status, main_output_error]
        Every run, in order (stored as strict JSON: a NaN error is the string "NaN").
    base : float
        The scene's evaluation step, s.
    """

    scenario: str
    adapter: str
    method: str
    k_min: int
    k_max: int
    max_bisections: int
    k_fail: int | None = None
    k_pass: int | None = None
    tried: list = field(default_factory=list)
    reference: bool = True
    base: float = EVALUATION_STEP

    def dt(self, k: int) -> float:
        """The step of candidate k, s."""
        return self.base / k

    def next_k(self) -> int | None:
        """The next k to run, or None when the search is over."""
        if not self.tried:
            return self.k_min
        if self.k_pass == self.k_min or (self.k_fail == self.k_max):
            return None
        if self.k_pass is None:
            return self.k_max
        if self.k_pass - self.k_fail <= 1 or len(self.tried) - 2 >= self.max_bisections:
            return None
        middle = round(math.sqrt(self.k_fail * self.k_pass))
        return min(max(middle, self.k_fail + 1), self.k_pass - 1)

    def record(self, k: int, row: dict) -> None:
        """Take the result of the run at k."""
        error = row.get("main_output_error")
        self.tried.append([self.dt(k), row.get("status"), error])
        if row.get("accurate") is None:
            self.reference = False
        if passes(row):
            self.k_pass = k if self.k_pass is None else min(self.k_pass, k)
        else:
            self.k_fail = k if self.k_fail is None else max(self.k_fail, k)

    def row(self) -> dict:
        """The sweep row: the largest passing step (NaN when none passed) and every try."""
        return {"sweep_id": f"{self.scenario}|{self.adapter}|{self.method}",
                "scenario": self.scenario, "adapter": self.adapter, "method": self.method,
                "largest_stable_dt": (self.dt(self.k_pass) if self.k_pass is not None
                                      else math.nan),
                "criterion": "ok and accurate" if self.reference else "ok (no reference)",
                "tried": dumps(self.tried, indent=None)}


def bisections(sweep) -> list[Bisection]:
    """One :class:`Bisection` per (scenario, adapter, method) of a campaign's ``SweepSpec``."""
    searches = []
    for scenario in sweep.scenarios:
        base = sweep.sample_steps.get(scenario, EVALUATION_STEP)
        k_min = max(1, math.ceil(base / sweep.dt_max - 1e-9))
        k_max = max(k_min, math.floor(base / sweep.dt_min + 1e-9))
        searches += [Bisection(scenario, adapter, method, k_min, k_max, sweep.max_bisections,
                               base=base)
                     for adapter in sweep.adapters for method in sweep.methods.get(adapter, ())]
    return searches


def stability_sweep(searches: list[Bisection], make_spec: Callable, run: Callable,
                    add_row: Callable) -> None:
    """Advance every search to its end, one batch of runs per round.

    Parameters
    ----------
    searches : list of Bisection
        The searches (:func:`bisections`); those whose row is already stored are left out by
        the caller.
    make_spec : callable
        ``make_spec(scenario, adapter, method, dt) -> CaseSpec``.
    run : callable
        ``run(specs) -> dict`` mapping each spec's ``case_id`` to its row (the executor).
    add_row : callable
        ``add_row(row)``, called as each search ends (the store's ``add_sweep``).
    """
    active = list(searches)
    while active:
        batch = {}
        for search in active:
            k = search.next_k()
            if k is None:
                add_row(search.row())
            else:
                batch[id(search)] = (search, k, make_spec(search.scenario, search.adapter,
                                                          search.method, search.dt(k)))
        rows = run([spec for _, _, spec in batch.values()]) if batch else {}
        for search, k, spec in batch.values():
            search.record(k, rows[spec.case_id])
        active = [search for search, _, _ in batch.values()]
