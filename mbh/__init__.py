"""mbh: load stored campaign results into pandas.

The harness itself lives in the ``harness`` and ``adapters`` packages; this package only names
the store's reading functions for users.

Examples
--------
>>> import mbh
>>> runs = mbh.list_runs()                 # manifests, oldest first
>>> cases = mbh.load_run(runs[-1]["run_id"])  # one row per case (harness.store.runs column names)
"""

from harness.common.errors import MbhError
from harness.store.compare import compare_runs
from harness.store.runs import RunStore, list_runs, load_run, results_root

__all__ = ["MbhError", "RunStore", "compare_runs", "list_runs", "load_run", "results_root"]
