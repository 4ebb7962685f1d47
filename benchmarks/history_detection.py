"""How well the history's step detection (:mod:`mbh._harness.report.changepoints`) finds steps in
synthetic histories with the noise measured on this machine, and how often it calls noise a step.

Run:  .venv/bin/python benchmarks/history_detection.py [--histories 100] [--runs 30] [--seed 1]

Each history has ``--runs`` runs.  Calibrated times carry multiplicative noise ``exp(σ · t₃ /
√3)`` (Student's t with 3 degrees of freedom, scaled to standard deviation σ: heavy tails like
the measured ones) at three levels of σ (natural log): 0.036 (two runs on the idle machine), 0.1,
and 0.25 (other jobs on the two cores); errors repeat to the bit between runs (as measured), here
with a 1 % jitter on top.  Per noise level it prints, over the histories:

* time step ×1.2 at a random run (5 … runs − 5): found (within 3 runs of it), found at the
  right run, mean delay (runs after the true one), false alarms (any other step reported);
* error step ×10: the same;
* noise only, and noise with one run ×3 slower: histories with any step reported (false alarms).

The figures of docs/history.md come from this script; nothing here is asserted (the slow test
``tests/report/test_history_detection.py`` runs it with fewer histories and checks the counts).
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass

import numpy as np

from mbh._harness.report.changepoints import ERROR, TIME, SeriesRule, detect_steps

#: Noise levels of calibrated time, σ of the natural log per run (see the module docstring).
NOISE_LEVELS = (0.036, 0.1, 0.25)
#: The steps of the done-when of issue 30.
TIME_STEP, ERROR_STEP, OUTLIER = 1.2, 10.0, 3.0
#: Level of the synthetic errors (rad) and their jitter (relative).
ERROR_LEVEL, ERROR_JITTER = 1e-6, 0.01
#: A step found within this many runs after its true run counts as found.
FOUND_WITHIN = 3


@dataclass
class Tally:
    """Counts over histories with one true step."""

    histories: int = 0
    found: int = 0
    at_run: int = 0
    delay_sum: int = 0
    false_alarms: int = 0

    def add(self, steps, true_index: int) -> None:
        self.histories += 1
        hits = [s.index - true_index for s in steps if 0 <= s.index - true_index <= FOUND_WITHIN]
        if hits:
            self.found += 1
            self.at_run += min(hits) == 0
            self.delay_sum += min(hits)
        self.false_alarms += len(steps) - (1 if hits else 0)

    def line(self, what: str) -> str:
        delay = self.delay_sum / self.found if self.found else float("nan")
        return (f"  {what}: found {self.found}/{self.histories}, at the right run "
                f"{self.at_run}/{self.histories}, mean delay {delay:.2f} runs, false alarms "
                f"{self.false_alarms}")


def time_noise(rng: np.random.Generator, runs: int, sigma: float) -> np.ndarray:
    """Multiplicative calibrated-time noise, shape (runs,)."""
    return np.exp(sigma * rng.standard_t(3, runs) / np.sqrt(3.0))


def stepped(rng, runs: int, noise: np.ndarray, factor: float, level: float) -> tuple:
    """(values, true index) of a history with one step of ``factor`` at a random run."""
    index = int(rng.integers(5, runs - 4))
    values = level * noise
    values[index:] *= factor
    return values, index


def measure(histories: int, runs: int, seed: int, sigma: float) -> dict[str, object]:
    """The counts of the module docstring at noise ``sigma``."""
    rng = np.random.default_rng(seed)
    time_step, error_step = Tally(), Tally()
    quiet = outlier = 0
    for _ in range(histories):
        values, index = stepped(rng, runs, time_noise(rng, runs, sigma), TIME_STEP, 1.0)
        time_step.add(detect_steps(values, TIME), index)
        jitter = 1.0 + ERROR_JITTER * rng.standard_normal(runs)
        values, index = stepped(rng, runs, jitter, ERROR_STEP, ERROR_LEVEL)
        error_step.add(detect_steps(values, ERROR), index)
        quiet += bool(detect_steps(time_noise(rng, runs, sigma), TIME))
        values = time_noise(rng, runs, sigma)
        values[int(rng.integers(0, runs))] *= OUTLIER
        outlier += bool(detect_steps(values, TIME))
    return {"time": time_step, "error": error_step, "noise_only": quiet, "outlier": outlier}


def report(histories: int, runs: int, seed: int, rule: SeriesRule = TIME) -> list[str]:
    """The printed lines (see the module docstring)."""
    lines = [f"{histories} histories of {runs} runs per noise level (seed {seed}); time rule "
             f"{rule}"]
    for sigma in NOISE_LEVELS:
        counts = measure(histories, runs, seed, sigma)
        lines += [f"σ = {sigma:g} (log of calibrated time, per run):",
                  counts["time"].line(f"time step ×{TIME_STEP:g}"),
                  counts["error"].line(f"error step ×{ERROR_STEP:g}"),
                  f"  noise only: histories with a false alarm {counts['noise_only']}/{histories}",
                  f"  one run ×{OUTLIER:g} slower: histories with a false alarm "
                  f"{counts['outlier']}/{histories}"]
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--histories", type=int, default=100)
    parser.add_argument("--runs", type=int, default=30)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    print("\n".join(report(args.histories, args.runs, args.seed)))


if __name__ == "__main__":
    main()
