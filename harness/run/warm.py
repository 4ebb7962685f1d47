"""The template every warm worker is forked from: imported once by the fork server
(:mod:`multiprocessing.forkserver`, the ``preload`` of
:class:`mbh._harness.run.executor.WorkerProcesses`), it sets the one-thread environment, imports numpy,
scipy, the harness and every registered engine, runs a few tiny cases so the compiled in-house
kernels are loaded from numba's cache, runs each of the campaign's methods over one sample
interval so what it loads on its first run is loaded once, and reads the campaign's scenarios and their stored
references (:mod:`mbh._harness.common.kept_files`), assembles their starts and computes what the
measuring stick derives from each reference alone.  Each case's process is then forked from this
state: a fresh process per case (a crash stays a row) that starts in milliseconds instead of
seconds (docs/speed.md, "Worker start").

Nothing here changes a result: the warm-up cases are thrown away, and every module-level cache they
fill (compiled code, loaded references) holds what a cold worker computes or loads for itself.
"""

from __future__ import annotations

import json
import multiprocessing.spawn
import os

from mbh._harness.common import waits
from mbh._harness.run.executor import WARM_SAY_ENV, WORKER_ENV

# Before numpy and the engines load their thread pools: one thread per case.
os.environ.update(WORKER_ENV)
# A compilation below (a machine where the kernels are not compiled yet) is said as the starting
# process says its own waits: the cases wait for this template.
if os.environ.get(WARM_SAY_ENV):
    waits.show_on_stderr()

#: The parts of multiprocessing's child preparation that re-run the starting process's main
#: module in the child: a user's script, or ``mbh._harness.cli``.  A case's process never needs it (its
#: work and spec are importable by name, as a cold worker needs them), and a script that starts a
#: campaign at its top level, without ``if __name__ == "__main__":``, would start the campaign
#: again in every case's process, which multiprocessing refuses (every case ``crashed``).
MAIN_MODULE_KEYS = ("init_main_from_name", "init_main_from_path")
_prepare = multiprocessing.spawn.prepare


def _prepare_without_main(data: dict) -> None:
    """multiprocessing's child preparation (sys.path, working folder, …) without
    :data:`MAIN_MODULE_KEYS`; installed in this template only, whose children are cases."""
    _prepare({key: value for key, value in data.items() if key not in MAIN_MODULE_KEYS})


multiprocessing.spawn.prepare = _prepare_without_main

#: (scenario, adapter, method, dt, t_end) run once in the template, their results discarded: the
#: planar and spatial in-house paths (default and best methods, which load most kernels) and an
#: engine.  A kernel they miss is loaded by the first case that needs it, as in a cold worker.
WARM_UP = (
    ("fourbar", "inhouse", "best", 1e-3, 0.02),
    ("fourbar", "inhouse", "default", 1e-3, 0.02),
    ("fourbar_spatial", "inhouse", "best", 1e-3, 0.02),
    ("fourbar", "mujoco", "best", 1e-3, 0.02),
)


def _warm_up() -> list[str]:
    """Import the engines and run :data:`WARM_UP`; returns what could not be warmed (a warm-up
    failure only costs the cases the load time it would have saved)."""
    from mbh._adapters import adapter_names, get_adapter
    from mbh._harness.measure.verdict import DEFAULT_ACCURACY, DEFAULT_BOUNDS
    from mbh._harness.run.row import run_spec
    from mbh._harness.run.spec import CaseSpec

    missed = []
    for name in adapter_names():
        try:
            get_adapter(name)
        except Exception as error:  # noqa: BLE001 — an engine that fails to import fails its cases
            missed.append(f"adapter {name}: {error}")
    for scene, adapter, method, dt, t_end in WARM_UP:
        try:
            run_spec(CaseSpec(scene, adapter, method, dt, t_end), DEFAULT_BOUNDS, DEFAULT_ACCURACY)
        except Exception as error:  # noqa: BLE001 — see above
            missed.append(f"{scene}/{adapter}/{method}: {error}")
    return missed


def _warm_methods() -> list[str]:
    """Run each method :data:`~mbh._harness.run.executor.WARM_METHODS_ENV` names (one per
    (adapter, method) of the campaign, on the scene and step of its first case) over one sample
    interval of its scene (:func:`mbh._harness.run.case.simulate_case`, results discarded): what
    a method loads on its first run (the in-house compiled loops and the kernels its formulation
    calls from Python, ~0.1–0.2 s each from numba's cache; an engine's libraries) is then loaded
    once here instead of in each of its cases.  A run that fails only leaves that load to its
    cases.  Returns what could not be warmed."""
    import math

    from mbh._adapters import get_adapter
    from mbh._harness.model import scenario
    from mbh._harness.run.case import simulate_case
    from mbh._harness.run.executor import WARM_METHODS_ENV

    missed = []
    for scene, adapter, method, dt in json.loads(os.environ.get(WARM_METHODS_ENV) or "[]"):
        try:
            mech = scenario.load(scene)
            steps = max(1, math.ceil(mech.sample_step / dt - 1e-9))
            simulate_case(get_adapter(adapter), mech, method, dt, steps * dt)
        except Exception as error:  # noqa: BLE001 — see _warm_up
            missed.append(f"{scene}/{adapter}/{method}: {error}")
    return missed


def _keep_scenarios() -> list[str]:
    """Read the scenarios :data:`~mbh._harness.run.executor.WARM_SCENARIOS_ENV` names, and their stored
    references, inside :func:`mbh._harness.common.kept_files.keeping`, assemble each scene's start
    (:func:`mbh._harness.neutral.start.initial_state`, cached per scene) and compute what the measuring
    stick derives from each reference alone (:func:`mbh._harness.measure.verdict.prepare_reference`)
    and, for the scenarios :data:`~mbh._harness.run.executor.WARM_CONDITIONED_ENV` names, the
    conditioning a failed case is labelled with
    (:func:`mbh._harness.measure.failure_label.reference_conditioning`), so the cases forked from
    here find them done (a reference that is not stored yet is not
    built: its cases read or build it as a cold worker does).  Returns what could not be read."""
    from mbh._harness.common.kept_files import keeping
    from mbh._harness.measure.failure_label import reference_conditioning
    from mbh._harness.measure.verdict import prepare_reference
    from mbh._harness.model import scenario
    from mbh._harness.neutral.start import initial_state
    from mbh._harness.run.executor import WARM_CONDITIONED_ENV, WARM_SCENARIOS_ENV
    from mbh._harness.store.reference_files import read_reference

    missed = []
    conditioned = set(json.loads(os.environ.get(WARM_CONDITIONED_ENV) or "[]"))
    with keeping():
        for name in json.loads(os.environ.get(WARM_SCENARIOS_ENV) or "[]"):
            try:
                mech = scenario.load(name)
                initial_state(mech)
                stored = read_reference(mech)
                if stored is not None:
                    prepare_reference(mech, stored[0])
                    if name in conditioned:
                        reference_conditioning(mech, stored[0])
            except Exception as error:  # noqa: BLE001 — its cases report it themselves
                missed.append(f"scenario {name}: {error}")
    return missed


#: What the warm-up could not do, for diagnostics (``python -c "import mbh._harness.run.warm"``).
#: The scenarios are read after the warm-up cases, so nothing those did can change what is kept.
MISSED = _warm_up() + _warm_methods() + _keep_scenarios()
