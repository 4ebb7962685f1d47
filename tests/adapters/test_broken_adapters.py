"""A broken third-party adapter gives rows whose reason names the adapter, its package and what
broke — an import error, a class that is no adapter, an exception in ``version()``, ``build``,
``_start`` or a step, states of the wrong shape — and never a traceback that ends a campaign.

The broken adapters are variations of the toy adapter (the adapter guide's package) declared by a
fake distribution ``mbh-broken-adapters 0.0.1`` (tests/adapters/conftest.py).
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys

import pytest

from mbh._harness.cli import main
from mbh._harness.measure.verdict import DEFAULT_ACCURACY, DEFAULT_BOUNDS
from mbh._harness.run.row import run_spec
from mbh._harness.run.spec import CaseSpec, load_campaign
from mbh._harness.store.runs import RunStore
from tests.adapters.conftest import write_distribution

PACKAGE = "mbh-broken-adapters 0.0.1"

BROKEN_MODULE = '''
from mbh_toy_adapter import ToyAdapter, ToyStepper


class NotAnAdapter:
    pass


class BadVersion(ToyAdapter):
    def version(self):
        raise OSError("no version file")


class BadBuild(ToyAdapter):
    def build(self, mechanism):
        return 1 / 0


class BadStart(ToyAdapter):
    def _start(self, model, spec, params, grid):
        raise KeyError("no engine")


class LostStepper(ToyStepper):
    def _step_to(self, t):
        if t > 0.1:
            raise RuntimeError("solver lost")
        super()._step_to(t)


class BadStep(ToyAdapter):
    def _start(self, model, spec, params, grid):
        return LostStepper(model, params["alpha"], grid.dt)


class FlatStepper(ToyStepper):
    def _states(self, t):
        states = super()._states(t)
        states.position = states.position[:, :2]
        return states


class BadShapes(ToyAdapter):
    def _start(self, model, spec, params, grid):
        return FlatStepper(model, params["alpha"], grid.dt)
'''

ENTRY_POINTS = {
    "broken_import": "mbh_broken_import:Adapter",
    "not_an_adapter": "mbh_broken_adapters:NotAnAdapter",
    "broken_version": "mbh_broken_adapters:BadVersion",
    "broken_build": "mbh_broken_adapters:BadBuild",
    "broken_start": "mbh_broken_adapters:BadStart",
    "broken_step": "mbh_broken_adapters:BadStep",
    "broken_shapes": "mbh_broken_adapters:BadShapes",
}

#: Adapter → (reason, failure time (s) or None, samples kept) of its four-bar case (dt 1e-2 s,
#: 0.2 s): every reason names the adapter and its package.
EXPECTED = {
    "broken_import": (f"adapter 'broken_import' from package {PACKAGE} cannot be loaded "
                      "(mbh_broken_import:Adapter): ModuleNotFoundError: No module named "
                      "'mbh_no_such_engine'", 0.0, 0),
    "not_an_adapter": (f"adapter 'not_an_adapter' from package {PACKAGE} cannot be loaded "
                       "(mbh_broken_adapters:NotAnAdapter): TypeError: "
                       "mbh_broken_adapters:NotAnAdapter is not a subclass of "
                       "mbh._adapters.base.Adapter", 0.0, 0),
    "broken_version": (f"adapter 'broken_version' from package {PACKAGE}, in version(): "
                       "OSError: no version file", 0.0, 0),
    "broken_build": (f"adapter 'broken_build' from package {PACKAGE}, in build: "
                     "ZeroDivisionError: division by zero", 0.0, 0),
    "broken_start": (f"adapter 'broken_start' from package {PACKAGE}, in _start: "
                     "KeyError: 'no engine'", 0.0, 0),
    # Samples at 0, 0.01, …, 0.1 s are kept; the step to 0.11 s raised.
    "broken_step": (f"adapter 'broken_step' from package {PACKAGE}, in the run: "
                    "RuntimeError: solver lost", 0.1, 11),
    "broken_shapes": (f"adapter 'broken_shapes' from package {PACKAGE}, in the run: "
                      "_states(0) returned position of shape (3, 2), expected (3, 3)", 0.0, 0),
}


def write_broken_package(folder) -> None:
    """The broken adapters' distribution metadata and modules, written into ``folder``."""
    write_distribution(folder, "mbh-broken-adapters", "0.0.1", ENTRY_POINTS)
    (folder / "mbh_broken_adapters.py").write_text(BROKEN_MODULE)
    (folder / "mbh_broken_import.py").write_text("import mbh_no_such_engine\n")


@pytest.fixture
def broken(toy, forget_modules):
    """The toy and the broken adapters registered in this process."""
    write_broken_package(toy)
    forget_modules("mbh_broken_adapters", "mbh_broken_import")


@pytest.mark.parametrize("name", EXPECTED)
def test_a_broken_adapter_gives_a_failed_row_naming_it(broken, name):
    result = run_spec(CaseSpec("fourbar", name, "best", 1e-2, 0.2), DEFAULT_BOUNDS,
                      DEFAULT_ACCURACY)
    reason, failure_time, samples = EXPECTED[name]
    assert (result.row["status"], result.row["reason"]) == ("failed", reason)
    assert result.trajectory.failure_time == failure_time
    assert len(result.trajectory.times) == samples


def test_a_campaign_takes_an_adapter_that_cannot_be_loaded(broken, tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text('[[group]]\nscenarios = ["fourbar"]\nadapters = ["broken_import", "toy"]\n'
                    'methods = ["best", "rk9"]\ndts = [1e-2]\n')
    with pytest.raises(ValueError, match=r"group\[0\]\.methods\[1\]: unknown toy method 'rk9'"):
        load_campaign(path)  # the loadable adapter's methods are checked ...
    path.write_text(path.read_text().replace('"toy"', '"inhouse"').replace('"rk9"', '"rk4+direct"'))
    cases = load_campaign(path).cases  # ... the unloadable one's cases become failed rows
    assert [(c.adapter, c.method) for c in cases] == [
        ("broken_import", "best"), ("broken_import", "rk4+direct"), ("inhouse", "best"),
        ("inhouse", "rk4+direct")]


def test_mbh_adapters_lists_a_broken_adapter_with_its_problem(broken, capsys):
    assert main(["adapters", "--json"]) == 1
    rows = {row["name"]: row for row in json.loads(capsys.readouterr().out)}
    assert rows["broken_import"]["problem"] == EXPECTED["broken_import"][0]
    assert rows["broken_version"]["problem"] == EXPECTED["broken_version"][0]
    assert (rows["broken_build"]["origin"], rows["broken_build"]["version"],
            rows["broken_build"]["problem"]) == ("mbh-broken-adapters", "toy 0.1.0", "")


@pytest.mark.slow  # 15 s: mbh run starts its warm worker template (every engine imported)
def test_mbh_run_stores_a_row_for_every_broken_case(toy_environment, tmp_path):
    """End to end: ``mbh run`` in its own worker processes, the adapters registered through
    ``PYTHONPATH``; the campaign completes with a row per case and the reasons above."""
    write_broken_package(tmp_path / "broken")
    environment = {**toy_environment, "PYTHONPATH": os.pathsep.join(
        [str(tmp_path / "broken"), toy_environment["PYTHONPATH"]])}
    campaign = tmp_path / "broken.toml"
    names = ", ".join(f'"{name}"' for name in [*EXPECTED, "toy"])
    campaign.write_text(f'calibration = false\n[[group]]\nscenarios = ["fourbar"]\n'
                        f'adapters = [{names}]\nmethods = ["best"]\ndts = [1e-2]\n'
                        f'[t_end]\n"*" = 0.2\n')
    done = subprocess.run([sys.executable, "-m", "mbh._harness.cli", "run", str(campaign), "--root",
                           str(tmp_path / "results"), "--quiet", "--workers", "2"],
                          env=environment, capture_output=True, text=True, timeout=600,
                          check=False)
    assert done.returncode == 0, done.stderr
    assert re.search(r": complete, 8 cases \(failed 7, ok 1\)", done.stdout), done.stdout
    run_id = re.search(r"^run (\S+):", done.stdout, re.MULTILINE).group(1)
    rows = RunStore.open(run_id, tmp_path / "results").cases().set_index("adapter")
    assert rows["reason"].to_dict() == {name: reason for name, (reason, _, _) in EXPECTED.items()
                                        } | {"toy": ""}
