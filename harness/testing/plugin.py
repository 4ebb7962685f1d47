"""The ``mbh`` pytest plugin (entry point ``pytest11``, registered by installing the package).

Thin wrappers over :mod:`mbh._harness.testing.cases` and :mod:`mbh._harness.testing.tolerances`:

* fixture ``mbh_runner`` (session): a :class:`~mbh._harness.testing.cases.CaseRunner` whose finished
  cases are kept for the whole session; a case of a scenario or adapter not selected on the
  command line is skipped with the reason;
* fixture ``mbh_reference``: ``mbh_reference("fourbar")`` → the scenario's verified reference
  (a :class:`~mbh._harness.model.trajectory.Trajectory`, None when it has none);
* fixture ``mbh_tolerances``: the :class:`~mbh._harness.testing.tolerances.Tolerances` of ``tolerances.toml``
  beside the test file (``--mbh-tolerances FILE`` names another), loaded once per file;
* options ``--mbh-scenarios A,B`` and ``--mbh-adapters X,Y``: only those run; a test
  parametrized with an unselected case is skipped at collection, with the reason;
* option ``--mbh-isolated`` and marker ``@pytest.mark.mbh_isolated``: the cases of every test
  (of the marked tests) run each in a worker process of its own, as a campaign's do, so an engine
  that crashes or hangs fails that test (status ``crashed`` or ``timeout``, the signal named) and
  the session goes on.  In-process is the default: isolation costs a process start per case
  (docs/formats/tolerances.md, "Isolated cases", gives the measured cost);
* options ``--mbh-record`` and ``--mbh-record-margin FACTOR``: record, then assert.  Every case a
  test looks up in ``mbh_tolerances`` is measured and its tolerances are written into that
  fixture's file at the session's end (:mod:`mbh._harness.testing.recording`: FACTOR, default
  :data:`RECORD_MARGIN`, times each measured error); each such test is reported failed with the
  files it recorded into, as pytest-regressions' ``--force-regen`` reports a regenerated file,
  so a recording session is never mistaken for a passing one.  Later sessions without the option
  assert against the files.

The assertion helpers are the plain functions of :mod:`mbh._harness.testing.tolerances`.  This module imports
nothing heavy at load time: pytest loads it in every session of this environment.
"""

from __future__ import annotations

from pathlib import Path

import pytest

#: File name of the tolerance table looked up beside a test file.
TOLERANCE_FILE = "tolerances.toml"
#: ``--mbh-record``'s default margin: a recorded tolerance is this many times the measured value.
RECORD_MARGIN = 10.0
#: The session's :class:`~mbh._harness.testing.recording.ToleranceRecording` under
#: ``--mbh-record``.
_RECORDING = pytest.StashKey()
#: Per test: the tolerance files it recorded into.
_RECORDED_INTO = pytest.StashKey()


def pytest_addoption(parser) -> None:
    group = parser.getgroup("mbh", "mbh multibody harness tolerance tests")
    group.addoption("--mbh-scenarios", default=None, metavar="A,B",
                    help="run only cases of these scenarios (comma-separated); the others are "
                         "skipped with the reason")
    group.addoption("--mbh-adapters", default=None, metavar="X,Y",
                    help="run only cases of these adapters (comma-separated); the others are "
                         "skipped with the reason")
    group.addoption("--mbh-isolated", action="store_true", default=False,
                    help="run every case in a worker process of its own (a crash fails one "
                         "test; the marker mbh_isolated does it for one test)")
    group.addoption("--mbh-tolerances", default=None, metavar="FILE",
                    help=f"tolerance file of the fixture mbh_tolerances (default: "
                         f"{TOLERANCE_FILE} beside each test file)")
    group.addoption("--mbh-record", action="store_true", default=False,
                    help="record the tolerances of every case a test looks up in mbh_tolerances "
                         "into its tolerance file (the measured errors times "
                         "--mbh-record-margin); each recording test is reported failed, as "
                         "recorded; run again without this option to assert against the file")
    group.addoption("--mbh-record-margin", type=float, default=RECORD_MARGIN, metavar="FACTOR",
                    help=f"--mbh-record: a recorded tolerance is FACTOR (> 1) times the measured "
                         f"value (default {RECORD_MARGIN:g})")


def pytest_configure(config) -> None:
    config.addinivalue_line("markers", "mbh_isolated: run this test's mbh cases each in a worker "
                                       "process of its own (a crash fails the test, not the session)")
    if config.getoption("--mbh-record"):
        config.stash[_RECORDING] = _recording(config)


def _recording(config):
    """The session's ToleranceRecording; a usage error for a bad margin or several processes."""
    from mbh._harness.testing.cases import ToleranceError
    from mbh._harness.testing.recording import ToleranceRecording

    if config.getoption("numprocesses", default=None) not in (None, 0):
        raise pytest.UsageError("--mbh-record records in one process: run it without -n "
                                "(pytest-xdist)")
    try:
        return ToleranceRecording(config.getoption("--mbh-record-margin"))
    except ToleranceError as error:
        raise pytest.UsageError(str(error)) from None


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item, call):
    """A test that recorded tolerances and passed is reported failed, naming the files."""
    report = yield
    files = item.stash.get(_RECORDED_INTO, None)
    if files and report.when == "call" and report.passed:
        report.outcome = "failed"
        report.longrepr = (f"mbh: tolerances recorded into {', '.join(sorted(map(str, files)))} "
                           f"(--mbh-record); run without --mbh-record to assert against them")
    return report


def pytest_sessionfinish(session) -> None:
    """Write the tolerance files recorded into this session (``--mbh-record``)."""
    recording = session.config.stash.get(_RECORDING, None)
    if recording is not None:
        recording.write()


def pytest_terminal_summary(terminalreporter, config) -> None:
    recording = config.stash.get(_RECORDING, None)
    for path in (recording.files if recording is not None else ()):
        terminalreporter.write_line(f"mbh: recorded {len(recording.files[path])} cases' "
                                    f"tolerances into {path} (margin "
                                    f"{recording.margin:g} x the measured values)")


def _selection(config):
    from mbh._harness.testing.cases import Selection, ToleranceError

    try:
        return Selection.parse(config.getoption("--mbh-scenarios"),
                               config.getoption("--mbh-adapters"))
    except ToleranceError as error:
        raise pytest.UsageError(str(error)) from None


def _specs(value) -> list:
    """The CaseSpecs in a parameter value (a case, or a list/tuple of cases)."""
    from mbh._harness.run.spec import CaseSpec

    values = value if isinstance(value, (list, tuple)) else [value]
    return [item for item in values if isinstance(item, CaseSpec)]


def pytest_collection_modifyitems(config, items) -> None:
    """Skip (with the reason) every test parametrized with a case not selected."""
    if not (config.getoption("--mbh-scenarios") or config.getoption("--mbh-adapters")):
        return
    selection = _selection(config)
    for item in items:
        callspec = getattr(item, "callspec", None)
        if callspec is None:
            continue
        reasons = [reason for value in callspec.params.values() for spec in _specs(value)
                   if (reason := selection.reason(spec)) is not None]
        if reasons:
            item.add_marker(pytest.mark.skip(reason=f"mbh: {reasons[0]}"))


class _SelectingRunner:
    """The session's CaseRunner, skipping the current test for a case not selected."""

    def __init__(self, runner, selection):
        self._runner, self._selection = runner, selection
        #: Whether the current test's cases run isolated (set before each test that uses it).
        self.isolated = False

    def __getattr__(self, name):
        return getattr(self._runner, name)

    def run(self, spec):
        reason = self._selection.reason(spec)
        if reason is not None:
            pytest.skip(f"mbh: {reason}")
        return self._runner.run(spec, isolated=self.isolated)

    def case(self, *args, **kwargs):
        from mbh._harness.testing.cases import case_spec

        return self.run(case_spec(*args, **kwargs))

    def steps(self, scenario_name, adapter, method, dts, t_end=None):
        return [self.case(scenario_name, adapter, method, dt, t_end) for dt in dts]


@pytest.fixture(scope="session")
def mbh_runner(request):
    """The session's :class:`mbh._harness.testing.cases.CaseRunner` (``run``, ``case``, ``steps``,
    ``reference``, ``calibration_s``)."""
    from mbh._harness.testing.cases import CaseRunner

    return _SelectingRunner(CaseRunner(), _selection(request.config))


@pytest.fixture(autouse=True)
def _mbh_isolation(request):
    """Before each test that uses ``mbh_runner``: isolate its cases when ``--mbh-isolated`` is given
    or the test is marked ``mbh_isolated`` (other tests never load the harness)."""
    if "mbh_runner" in request.fixturenames:
        request.getfixturevalue("mbh_runner").isolated = bool(
            request.config.getoption("--mbh-isolated")
            or request.node.get_closest_marker("mbh_isolated"))


@pytest.fixture(scope="session")
def mbh_reference(mbh_runner):
    """``mbh_reference(scenario_name)`` → its verified reference (None when it has none)."""
    return mbh_runner.reference


@pytest.fixture(scope="session")
def _mbh_tolerance_files():
    return {}


class _RecordingTolerances:
    """``mbh_tolerances`` under ``--mbh-record``: ``for_case(case)`` runs the case (or takes it
    from the session), records its tolerances for ``path`` and returns the measured status
    alone, which the test's assertion then holds."""

    def __init__(self, path: Path, recording, runner, item):
        self.path, self._recording, self._runner, self._item = path, recording, runner, item

    def for_case(self, spec):
        tolerance = self._recording.record(self.path, self._runner.run(spec))
        self._item.stash.setdefault(_RECORDED_INTO, set()).add(self.path)
        return tolerance


@pytest.fixture
def mbh_tolerances(request, _mbh_tolerance_files):
    """The :class:`mbh._harness.testing.tolerances.Tolerances` beside the test file (or
    ``--mbh-tolerances``); ``mbh_tolerances.for_case(case)`` → the case's tolerances.  Under
    ``--mbh-record`` the file is recorded instead (the module notes)."""
    from mbh._harness.testing.tolerances import Tolerances

    chosen = request.config.getoption("--mbh-tolerances")
    path = Path(chosen) if chosen else Path(request.path).parent / TOLERANCE_FILE
    recording = request.config.stash.get(_RECORDING, None)
    if recording is not None:
        return _RecordingTolerances(path.resolve(), recording,
                                    request.getfixturevalue("mbh_runner"), request.node)
    if path not in _mbh_tolerance_files:
        _mbh_tolerance_files[path] = Tolerances(path)
    return _mbh_tolerance_files[path]
