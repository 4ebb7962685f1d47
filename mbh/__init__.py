"""mbh: the harness's Python API.

Load a scene or build one, run one case or a whole campaign, read the stored runs.  The public API
is three modules: this one, :mod:`mbh.adapters` (the contract an adapter for your own solver
implements) and :mod:`mbh.testing` (tolerance assertions for your test suite).  Every module
whose name starts with an underscore (``mbh._harness``, ``mbh._adapters``) is private and may
change between releases.  docs/api.md documents each public name with runnable examples (the
tests run them).

Examples
--------
>>> import mbh
>>> fourbar = mbh.load_scenario("fourbar")
>>> result = mbh.run_case(fourbar, "mujoco", "best", dt=1e-3, t_end=0.1)
>>> print(result.status)
ok
>>> frame = result.to_frame()              # one row, the columns of a stored run
>>> frame.loc[0, "adapter"]
'mujoco'
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

from mbh._harness.common.errors import MbhError
from mbh._harness.measure.verdict import Bounds
from mbh._harness.model.builder import MechanismBuilder
from mbh._harness.model.mechanism import Mechanism
from mbh._harness.model.scenario import ScenarioError, scenario_names
from mbh._harness.model.scenario import load as load_scenario
from mbh._harness.run.case import CaseResult
from mbh._harness.run.single import CaseInputError
from mbh._harness.run.single import run_one as run_case
from mbh._harness.run.spec import CampaignError, campaign_names, load_campaign
from mbh._harness.store.location import results_root
from mbh._harness.store.manifest import list_runs

#: The names whose modules import pandas, loaded on first use (PEP 562): every import of a private
#: module (``mbh._harness…``) runs this file first, a campaign's worker template and every case's
#: process among them, and pandas would add ~0.4 s to each of their starts.
_LAZY = {"RunStore": "mbh._harness.store.runs", "load_run": "mbh._harness.store.runs",
         "compare_runs": "mbh._harness.store.compare"}

if TYPE_CHECKING:  # what the documentation's static reader and type checkers see
    from mbh._harness.store.compare import compare_runs
    from mbh._harness.store.runs import RunStore, load_run


def __getattr__(name: str):
    """The public name ``name`` of :data:`_LAZY`, imported on first use."""
    if name not in _LAZY:
        raise AttributeError(f"module 'mbh' has no attribute {name!r}")
    value = getattr(importlib.import_module(_LAZY[name]), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_LAZY})


def run_campaign(campaign, *, adapters=(), workers: int | None = None, root=None,
                 reuse: bool = False, resume: str | None = None, quiet: bool = True) -> RunStore:
    """Run a campaign into the result store, as ``mbh run`` does.

    Parameters
    ----------
    campaign : str or Path
        A shipped campaign name or a campaign file (its scenarios by shipped name or by path
        relative to the file).
    adapters : iterable of Adapter subclasses or instances
        Your own adapters, not registered, which the file names by their ``name`` (and
        ``adapters = "all"`` includes).  Each case runs in a worker process of its own, which
        imports the class by name: define it at the top level of an importable module (not in
        the script being run, nor inside a function); an instance must pickle.  Their cases are
        never taken from nor kept in the ``reuse`` cache.
    workers : int, optional
        Worker processes (default: the cores).
    root : path, optional
        Results root (default :func:`results_root`).
    reuse : bool
        Copy identical cases of registered adapters from the cache instead of running them.
    resume : str, optional
        Run id of an interrupted run of the same campaign file to complete.
    quiet : bool
        No progress bar and no notes on stderr (default for the API; the notes are in the
        manifest's ``notes`` either way, e.g. the third-party adapters ``"all"`` took in).

    Returns
    -------
    RunStore
        The finished run: ``.run_id``, ``.cases()`` (a DataFrame), ``.manifest``.

    Raises
    ------
    CampaignError
        The file does not validate (every problem, naming the file and field).
    MbhError
        A run that cannot start as asked: a given adapter that cannot stand for one or cannot
        reach the worker processes (the message says what it needs), a bad worker count, an
        unknown run to resume.
    """
    from mbh._harness.run.campaign import run_campaign as run

    return run(load_campaign(campaign, adapters), workers=workers, root=root, reuse=reuse,
               resume=resume, quiet=quiet)


__all__ = ["Bounds", "CampaignError", "CaseInputError", "CaseResult", "Mechanism",
           "MechanismBuilder", "MbhError", "RunStore", "ScenarioError", "campaign_names",
           "compare_runs", "list_runs", "load_campaign", "load_run", "load_scenario",
           "results_root", "run_campaign", "run_case", "scenario_names"]
