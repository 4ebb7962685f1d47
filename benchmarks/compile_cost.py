"""What an ``mbh`` command compiles on a machine where nothing is compiled yet, and how long each
function takes.

Run:  .venv/bin/python benchmarks/compile_cost.py [--passes] simulate fourbar --adapter inhouse \\
          --method rk4+direct --dt 1e-3 --json

The command runs in this process with an empty cache (a new temporary ``MBH_CACHE_HOME``, and
``MBH_RESULTS_DIR`` beside it), while a listener on numba's ``numba:compile`` events records each
compilation.  It prints the command's wall time, the time numba spent compiling, and per
function the time spent in the function itself (its callees' compilations taken out) and in all
(inclusive), most first.  Generated functions (``cfunc``) are compiled without these events: their
time is the rest of the wall time with the imports and the run.  With ``--passes`` it also prints,
summed over every function, the time of each stage of numba's pipeline (its ``pipeline_times``:
bytecode, inlining, type inference, lowering with LLVM's optimisation and machine code …), type
inference without the callees it compiled inside it, and each listed function's three largest
stages.  Numbers are measured on the machine that runs it; nothing is asserted (docs/speed.md,
"What a first run compiles").
"""

from __future__ import annotations

import collections
import os
import sys
import tempfile
import time

from numba.core import event

#: Functions printed, most time first.
SHOWN = 40
#: numba's type-inference stage, inside which a function's callees are compiled.
TYPING = "nopython_type_inference"


class CompileTimes(event.Listener):
    """Inclusive and exclusive compile time per function, s, and how often it was compiled."""

    def __init__(self):
        self.inclusive = collections.defaultdict(float)
        self.exclusive = collections.defaultdict(float)
        self.count = collections.Counter()
        #: Per function, numba's stage → s summed over its compilations (:func:`pipeline_stages`).
        self.stages = collections.defaultdict(collections.Counter)
        self._open: list[list] = []  # [name, start, time of the callees compiled inside]

    def on_start(self, event_):
        function = event_.data["dispatcher"].py_func
        self._open.append([f"{function.__module__}.{function.__qualname__}",
                           time.perf_counter(), 0.0])

    def on_end(self, event_):
        name, began, callees = self._open.pop()
        took = time.perf_counter() - began
        self.inclusive[name] += took
        self.exclusive[name] += took - callees
        self.count[name] += 1
        if self._open:
            self._open[-1][2] += took
        stages = pipeline_stages(event_.data["dispatcher"].overloads.get(
            tuple(event_.data["args"])))
        if stages:
            # The callees compiled while this function's types were inferred are theirs.
            stages[TYPING] -= callees
            self.stages[name].update(stages)


def pipeline_stages(result) -> dict[str, float]:
    """Stage name → s of one compilation (``CompileResult.metadata["pipeline_times"]``: each
    pass's init, run and finalize times, its ordinal prefix dropped); empty when numba kept none."""
    stages = collections.Counter()
    timings = (getattr(result, "metadata", None) or {}).get("pipeline_times", {})
    for passes in timings.values():
        for numbered, times in passes.items():
            stages[numbered.split("_", 1)[-1]] += times.init + times.run + times.finalize
    return stages


def main(argv: list[str]) -> None:
    by_stage = "--passes" in argv
    argv = [arg for arg in argv if arg != "--passes"]
    folder = tempfile.mkdtemp(prefix="mbh-compile-cost-")
    os.environ["MBH_CACHE_HOME"] = os.path.join(folder, "cache")
    os.environ["MBH_RESULTS_DIR"] = os.path.join(folder, "results")
    times = CompileTimes()
    event.register("numba:compile", times)
    began = time.perf_counter()
    from mbh._harness.cli import main as mbh

    mbh(argv)
    wall = time.perf_counter() - began
    print(f"wall {wall:.1f} s, numba compiling {sum(times.exclusive.values()):.1f} s "
          f"(cache {folder})", file=sys.stderr)
    print(f"{'own s':>8} {'all s':>8} {'times':>5}  function", file=sys.stderr)
    for name, own in sorted(times.exclusive.items(), key=lambda item: -item[1])[:SHOWN]:
        largest = ""
        if by_stage:
            largest = "  " + ", ".join(f"{stage} {seconds:.1f}" for stage, seconds
                                       in times.stages[name].most_common(3))
        print(f"{own:8.2f} {times.inclusive[name]:8.2f} {times.count[name]:5d}  {name}{largest}",
              file=sys.stderr)
    if by_stage:
        total = sum(times.stages.values(), collections.Counter())
        print("numba's stages, s summed over every function (type inference without the "
              "callees compiled in it):", file=sys.stderr)
        for stage, seconds in total.most_common(12):
            print(f"{seconds:8.2f}  {stage}", file=sys.stderr)


if __name__ == "__main__":
    main(sys.argv[1:])
