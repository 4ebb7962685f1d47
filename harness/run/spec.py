"""Campaign files (TOML, one campaign per file in ``campaigns/``): which cases a run computes.

A campaign is scenarios × adapters × methods × step sizes, written as one or more ``[[group]]``
blocks, plus the run's settings.  The validator walks the whole file, collects every problem with
its field path and raises one :class:`CampaignError` listing them all (the style of
:mod:`mbh._harness.model.scenario`), before anything runs.  Expansion into :class:`CaseSpec` objects is
deterministic; a case produced twice is kept once, with the earlier group's settings.

Adapters are named as registered (built-in, or installed by an entry point), or given to
:func:`load_campaign` as classes or instances (a solver without packaging: its name is the
adapter's ``name``).  ``adapters = "all"`` is every registered adapter and every given one; the
third-party ones it took in are said in :attr:`Campaign.notes`.

The file format (keys, defaults, the rules checked, expansion order, an example) is documented in
``docs/formats/campaign.md``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from mbh._adapters import (AdapterChoiceError, AdapterLoadError, adapter_names, get_adapter,
                          registrations, resolve_adapter)
from mbh._adapters.base import Adapter, steps_in
from mbh._harness.model import scenario
from mbh._harness.model.mechanism import Mechanism
from mbh._harness.model.timegrid import steps_per_sample
from mbh._harness.model.toml_fields import Problem, _Collector, _join, finite_number, read_toml
from mbh._harness.measure.verdict import DEFAULT_ACCURACY, DEFAULT_BOUNDS, Bounds
from mbh._harness.common.errors import MbhError
from mbh._harness.common.locations import shipped

CAMPAIGN_DIR = shipped("campaigns")

#: Settings when a file does not give them.
DEFAULT_REPETITIONS = 1
DEFAULT_TIMEOUT_S = 600.0
#: Key of the ``[t_end]`` table that applies to every scenario not named in it.
EVERY_SCENARIO = "*"

_TOP_KEYS = {"description", "repetitions", "timeout_s", "accuracy", "calibration", "bounds",
             "t_end", "group", "sweep"}
_GROUP_KEYS = {"scenarios", "except", "adapters", "methods", "dts", "repetitions", "timeout_s",
               "t_end"}
_SWEEP_KEYS = {"scenarios", "except", "adapters", "methods", "dt_min", "dt_max", "max_bisections"}
_BOUND_KEYS = {f.name for f in fields(Bounds)}


@dataclass(frozen=True)
class CaseSpec:
    """One case of a campaign.

    Attributes
    ----------
    scenario : str
        Shipped scenario name, family member (``family@parameter``) or the absolute path of a
        scenario file (a campaign names it relative to itself; :meth:`_Reader._scenario_name`).
    adapter : str
        The adapter's name: registered, or the ``name`` of an adapter given as a class or an
        instance (:func:`load_campaign`, :func:`mbh.run_case`).
    method : str
        Method string ``NAME[:key=value,...]`` as written in the campaign.
    dt : float
        Step, s; divides the evaluation step 0.01 s and ``t_end``.
    t_end : float
        Duration, s: the scenario's unless the campaign overrides it.
    repetitions : int
        Timing repetitions (>= 1); the metrics come from the first run.
    timeout_s : float
        Wall-clock limit of the whole case (all repetitions), s.
    """

    scenario: str
    adapter: str
    method: str
    dt: float
    t_end: float
    repetitions: int = DEFAULT_REPETITIONS
    timeout_s: float = DEFAULT_TIMEOUT_S

    @property
    def case_id(self) -> str:
        """Stable, readable and unique: ``"fourbar|mujoco|best|0.001|4.0"``."""
        return f"{self.scenario}|{self.adapter}|{self.method}|{self.dt!r}|{self.t_end!r}"


@dataclass(frozen=True)
class SweepSpec:
    """The stability sweep of a campaign.

    Attributes
    ----------
    scenarios, adapters : tuple of str
    methods : dict
        Adapter name → tuple of method strings.
    dt_min, dt_max : float
        Bisection bounds, s; each divides 0.01 s.  Candidates are a scene's evaluation step
        (``sample_steps``, 0.01 s unless the scene declares a finer one) / k for integer k.
    max_bisections : int
    t_end : dict
        Scenario name → duration of its sweep runs, s (the campaign's top-level ``[t_end]``
        overrides, else the scenario's duration).
    sample_steps : dict
        Scenario name → its evaluation step, s.
    """

    scenarios: tuple[str, ...]
    adapters: tuple[str, ...]
    methods: dict[str, tuple[str, ...]]
    dt_min: float
    dt_max: float
    max_bisections: int
    t_end: dict[str, float] = dataclasses.field(default_factory=dict)
    sample_steps: dict[str, float] = dataclasses.field(default_factory=dict)


@dataclass(frozen=True)
class Campaign:
    """A validated, expanded campaign file.

    Attributes
    ----------
    name : str
        The file's stem.
    path : Path
    text : str
        The file itself (stored with every run).
    cases : tuple of CaseSpec
        Expanded, in deterministic order, without duplicates.
    bounds : Bounds
        The verdict's bounds.
    accuracy : float
        Threshold on the main output's error, rad or m.
    sweep : SweepSpec or None
    calibration : bool
        Whether a run starts with the calibration case.
    description : str
    notes : tuple of str
        What a reader of the run must know about how the file was read: the third-party
        adapters that ``adapters = "all"`` took in.
    given_adapters : tuple of (str, type or Adapter)
        The adapters given to :func:`load_campaign` as classes or instances, by name, as given.
    """

    name: str
    path: Path
    text: str
    cases: tuple[CaseSpec, ...]
    bounds: Bounds
    accuracy: float
    sweep: SweepSpec | None
    calibration: bool
    description: str = ""
    notes: tuple[str, ...] = ()
    given_adapters: tuple[tuple[str, Any], ...] = ()


class CampaignError(MbhError, ValueError):
    """Raised once per file with every :class:`~mbh._harness.model.scenario.Problem` found."""

    def __init__(self, problems: list[Problem]):
        self.problems = problems
        super().__init__("\n".join(str(p) for p in problems))


def campaign_path(name_or_path: str | Path) -> Path:
    """``campaigns/<name>.toml`` for a shipped name, else the path as given (a ``.toml`` file)."""
    path = Path(name_or_path)
    return path if path.suffix == ".toml" else CAMPAIGN_DIR / f"{name_or_path}.toml"


def campaign_names() -> list[str]:
    """Names of the shipped campaigns, sorted."""
    return sorted(p.stem for p in CAMPAIGN_DIR.glob("*.toml"))


def main_output(mech: Mechanism) -> str | None:
    """Name of the scenario's main output: its first declared output (the crank angle of the
    shipped linkages, the crank tip's x of ``double_fourbar``), rad or m; None for a mechanism
    that declares none (a run then has no main-output error, its other metrics stand)."""
    return mech.outputs[0].name if mech.outputs else None


def load_campaign(name_or_path: str | Path, adapters=()) -> Campaign:
    """Load, validate and expand a campaign by shipped name or by path.

    Parameters
    ----------
    name_or_path : str or Path
    adapters : iterable of Adapter subclasses or instances
        Adapters that are not registered, which the file names by their ``name``
        (:func:`mbh._adapters.resolve_adapter`); ``adapters = "all"`` includes them.

    Raises
    ------
    CampaignError
        With every problem found, each naming the file and the field.
    AdapterChoiceError
        A given adapter that cannot stand for one, or two given adapters of one name.
    AdapterLoadError
        A given adapter class that fails to construct.
    """
    given = _given(adapters)
    path = campaign_path(name_or_path)
    file = str(path)
    try:
        text, document = read_toml(path)
    except FileNotFoundError:
        known = ", ".join(campaign_names())
        raise CampaignError([Problem(file, "-", f"no such campaign file (shipped: {known})")]) \
            from None
    except ValueError as error:
        raise CampaignError([Problem(file, "-", str(error))]) from None
    return _Reader(file, document, path.resolve().parent, given).read(path, text)


def _given(adapters) -> dict[str, tuple[Any, Adapter]]:
    """Name → (the class or instance as given, the adapter it stands for)."""
    given = {}
    for adapter in adapters:
        if isinstance(adapter, str):
            raise AdapterChoiceError(f"adapters: give classes or instances, not the name "
                                     f"{adapter!r} (registered adapters are named in the file)")
        resolved = resolve_adapter(adapter)
        if resolved.name in given:
            raise AdapterChoiceError(f"adapters: two adapters given are named {resolved.name!r}")
        given[resolved.name] = (adapter, resolved)
    return given


class _Unloadable:
    """Stands in for a registered adapter that cannot be loaded: its method strings are taken
    unchecked, and its cases run and fail with the load error, naming the adapter and its
    package, as their reason (docs/design.md, rule 6: a row, never a refused campaign)."""

    def method_spec(self, method: str) -> None:
        """Accepts every method string."""


class _Reader:
    """Turns a parsed campaign document into a :class:`Campaign`, collecting problems."""

    def __init__(self, file: str, document: dict, folder: Path,
                 given: dict[str, tuple[Any, Adapter]]):
        self.c = _Collector(file)
        self.document = document
        self.folder = folder
        self.given = given
        self._mechanisms: dict[str, Mechanism | None] = {}
        self._adapters: dict[str, Adapter | _Unloadable] = {
            name: resolved for name, (_, resolved) in given.items()}
        self._methods_checked: set[tuple[str, str]] = set()
        #: Third-party registered adapters that ``adapters = "all"`` took in: name → label.
        self._through_all: dict[str, str] = {}

    def read(self, path: Path, text: str) -> Campaign:
        doc, c = self.document, self.c
        c.unknown_keys(doc, _TOP_KEYS, "")
        description = doc.get("description", "")
        if not isinstance(description, str):
            c.add("description", f"expected a string, got {description!r}")
        repetitions = self._count(doc, "repetitions", "", DEFAULT_REPETITIONS)
        timeout = self._positive(doc, "timeout_s", "", DEFAULT_TIMEOUT_S)
        accuracy = self._positive(doc, "accuracy", "", DEFAULT_ACCURACY)
        calibration = doc.get("calibration", True)
        if not isinstance(calibration, bool):
            c.add("calibration", f"expected true or false, got {calibration!r}")
        bounds = self._bounds(doc.get("bounds", {}))
        t_end = self._durations(doc.get("t_end", {}), "t_end")
        cases = self._groups(doc, repetitions, timeout, t_end)
        sweep = self._sweep(doc["sweep"], t_end) if "sweep" in doc else None
        if c.problems:
            raise CampaignError(c.problems)
        return Campaign(name=path.stem, path=path, text=text, cases=tuple(cases), bounds=bounds,
                        accuracy=accuracy, sweep=sweep, calibration=calibration,
                        description=description, notes=self._notes(),
                        given_adapters=tuple((name, adapter)
                                             for name, (adapter, _) in self.given.items()))

    def _notes(self) -> tuple[str, ...]:
        if not self._through_all:
            return ()
        return (f'adapters = "all" took in the third-party {", ".join(self._through_all.values())}'
                f'; name the adapters in the file to leave '
                f'{"it" if len(self._through_all) == 1 else "them"} out',)

    # --- settings -----------------------------------------------------------------------------

    def _count(self, table: dict, key: str, path: str, default: int, least: int = 1) -> int:
        value = table.get(key, default)
        if isinstance(value, bool) or not isinstance(value, int) or value < least:
            self.c.add(_join(path, key), f"expected an integer >= {least}, got {value!r}")
            return default
        return value

    def _positive(self, table: dict, key: str, path: str, default: float | None) -> float | None:
        value = self.c.number(table, key, path, default=default, positive=True)
        return default if value is None else value

    def _bounds(self, table: Any) -> Bounds:
        if not isinstance(table, dict):
            self.c.add("bounds", f"expected a table, got {table!r}")
            return DEFAULT_BOUNDS
        self.c.unknown_keys(table, _BOUND_KEYS, "bounds")
        values = {key: self.c.number(table, key, "bounds", positive=True)
                  for key in _BOUND_KEYS if key in table}
        return Bounds(**{key: value for key, value in values.items() if value is not None})

    def _durations(self, table: Any, path: str) -> dict[str, float]:
        """A ``t_end`` table: scenario name (or ``"*"``) → s, each checked against it."""
        if not isinstance(table, dict):
            self.c.add(path, f"expected a table of scenario = seconds, got {table!r}")
            return {}
        durations = {}
        for written in table:
            value = self.c.number(table, written, path, positive=True)
            key = self._scenario_name(written)
            if key != EVERY_SCENARIO:
                mech = self._mechanism(key, _join(path, written))
                if mech is not None and value is not None and value > mech.duration:
                    self.c.add(_join(path, written), f"{value!r} s is beyond the scenario's duration "
                               f"{mech.duration!r} s (its reference ends there)")
                    value = None
            if value is not None:
                durations[key] = value
        return durations

    # --- names --------------------------------------------------------------------------------

    def _scenario_name(self, written: Any) -> Any:
        """A scenario as the cases name it: a file (``*.toml``) relative to the campaign file
        becomes its absolute path, so a user's campaign and scenes live side by side in the
        user's repository; names (shipped scenes, family members) stay as written."""
        if isinstance(written, str) and written.endswith(".toml"):
            try:
                return str((self.folder / written).resolve())
            except (OSError, ValueError, RuntimeError):  # a NUL in the name, a symlink loop
                return written  # the scenario loader names the problem
        return written

    def _mechanism(self, name: Any, field: str) -> Mechanism | None:
        if not isinstance(name, str):
            self.c.add(field, f"expected a scenario name, got {name!r}")
            return None
        if name not in self._mechanisms:
            if not name.endswith(".toml") and not scenario.is_scenario_name(name):
                known = ", ".join(scenario.scenario_names())
                self.c.add(field, f"unknown scenario {name!r} (known: {known})")
                self._mechanisms[name] = None
                return None
            try:
                self._mechanisms[name] = scenario.load(name)
            except scenario.ScenarioError as error:
                self.c.add(field, f"scenario {name!r} does not load: {error}")
                self._mechanisms[name] = None
                return None
        return self._mechanisms[name]

    def _known_adapters(self) -> list[str]:
        """The registered adapters' names, then the given ones'."""
        return [*adapter_names(), *self.given]

    def _note_third_party(self) -> None:
        """Remember the third-party registered adapters, which ``adapters = "all"`` took in,
        for :attr:`Campaign.notes`."""
        for name, found in registrations().items():
            if not found.built_in:
                self._through_all[name] = found.label

    def _adapter(self, name: Any, field: str) -> Adapter | _Unloadable | None:
        """The adapter ``name`` (an :class:`_Unloadable` when a registered one cannot be
        loaded); None, with the problem recorded, for a name that is neither registered nor
        given."""
        known = self._known_adapters()
        if not isinstance(name, str) or name not in known:
            self.c.add(field, f"unknown adapter {name!r} (known: {', '.join(known)})")
            return None
        if name not in self._adapters:
            try:
                self._adapters[name] = get_adapter(name)
            except AdapterLoadError:
                self._adapters[name] = _Unloadable()
        return self._adapters[name]

    def _names(self, table: dict, key: str, path: str, everything: list[str]) -> list[str]:
        """A list of names, or ``"all"``; problems recorded, [] when unusable."""
        value = self.c.required(table, key, path)
        if value == "all":
            return list(everything)
        if (not isinstance(value, list) or not value
                or not all(isinstance(v, str) for v in value)):
            if value is not None:
                self.c.add(_join(path, key), f'expected "all" or a non-empty list of names, '
                           f"got {value!r}")
            return []
        return value

    def _scenarios(self, table: dict, path: str) -> list[tuple[str, Mechanism]]:
        names = self._without_excepted(
            table, path, self._names(table, "scenarios", path, scenario.scenario_names()))
        found = [(n, self._mechanism(n, f"{_join(path, 'scenarios')}[{i}]"))
                 for i, n in enumerate(map(self._scenario_name, names))]
        return [(n, mech) for n, mech in found if mech is not None]

    def _without_excepted(self, table: dict, path: str, names: list[str]) -> list[str]:
        """``names`` less the table's ``except`` list, which only ``scenarios = "all"`` takes and
        which must name scenarios of it; problems recorded, ``names`` unchanged then."""
        if "except" not in table:
            return names
        field, left_out = _join(path, "except"), table["except"]
        if table.get("scenarios") != "all":
            self.c.add(field, 'allowed only with scenarios = "all"')
            return names
        if not isinstance(left_out, list) or not all(isinstance(n, str) for n in left_out):
            self.c.add(field, f"expected a list of scenario names, got {left_out!r}")
            return names
        for i, name in enumerate(left_out):
            if name not in names:
                self.c.add(f"{field}[{i}]", f"unknown scenario {name!r} (known: "
                           f"{', '.join(names)})")
        return [name for name in names if name not in left_out]

    def _methods(self, table: dict, path: str) -> dict[str, list[str]]:
        """Adapter → method strings, from ``adapters`` + a ``methods`` list or a ``methods``
        table; each method checked by the adapter."""
        methods = self.c.required(table, "methods", path)
        field = _join(path, "methods")
        if isinstance(methods, dict):
            if "adapters" in table:
                self.c.add(_join(path, "adapters"), "not allowed when methods is a table "
                           "(its keys name the adapters)")
            chosen = {name: (value, f"{field}.{name}") for name, value in methods.items()}
            fields_of = {name: f"{field}.{name}" for name in methods}
        elif isinstance(methods, list):
            adapters = self._names(table, "adapters", path, self._known_adapters())
            if table.get("adapters") == "all":
                self._note_third_party()
            chosen = {name: (methods, field) for name in adapters}
            fields_of = {name: f"{_join(path, 'adapters')}[{i}]" for i, name in enumerate(adapters)}
        else:
            if methods is not None:
                self.c.add(field, f"expected a list of method strings or a table of them per "
                           f"adapter, got {methods!r}")
            return {}
        result = {}
        for name, (strings, strings_field) in chosen.items():
            adapter = self._adapter(name, fields_of[name])
            valid = self._method_strings(adapter, name, strings, strings_field)
            if adapter is not None and valid:
                result[name] = valid
        return result

    def _method_strings(self, adapter: Adapter | _Unloadable | None, name: str, strings: Any,
                        field: str) -> list[str]:
        if not isinstance(strings, list) or not strings:
            self.c.add(field, f"expected a non-empty list of method strings, got {strings!r}")
            return []
        valid = []
        for i, method in enumerate(strings):
            if not isinstance(method, str):
                self.c.add(f"{field}[{i}]", f"expected a method string, got {method!r}")
                continue
            if adapter is None:
                continue
            if (name, method) not in self._methods_checked:
                try:
                    adapter.method_spec(method)
                except ValueError as error:
                    self.c.add(f"{field}[{i}]", str(error))
                    continue
                self._methods_checked.add((name, method))
            valid.append(method)
        return valid

    def _steps(self, table: dict, path: str) -> list[tuple[int, float]]:
        """(index, dt) of every valid step of a ``dts`` list."""
        value = self.c.required(table, "dts", path)
        field = _join(path, "dts")
        if not isinstance(value, list) or not value:
            if value is not None:
                self.c.add(field, f"expected a non-empty list of steps (s), got {value!r}")
            return []
        steps = []
        for i, dt in enumerate(value):
            checked = self._step(dt, f"{field}[{i}]")
            if checked is not None:
                steps.append((i, checked))
        return steps

    def _step(self, dt: Any, field: str) -> float | None:
        if not finite_number(dt) or dt <= 0:
            self.c.add(field, f"expected a finite step > 0 (s), got {dt!r}")
            return None
        try:
            steps_per_sample(float(dt))
        except ValueError as error:
            self.c.add(field, str(error))
            return None
        return float(dt)

    # --- groups -------------------------------------------------------------------------------

    def _groups(self, doc: dict, repetitions: int, timeout: float,
                t_end: dict[str, float]) -> list[CaseSpec]:
        groups = doc.get("group")
        if not isinstance(groups, list) or not groups or not all(isinstance(g, dict)
                                                                 for g in groups):
            self.c.add("group", "expected one or more [[group]] tables")
            return []
        cases: dict[str, CaseSpec] = {}
        for index, group in enumerate(groups):
            for case in self._group(group, f"group[{index}]", repetitions, timeout, t_end):
                cases.setdefault(case.case_id, case)
        return list(cases.values())

    def _group(self, group: dict, path: str, repetitions: int, timeout: float,
               t_end: dict[str, float]) -> list[CaseSpec]:
        self.c.unknown_keys(group, _GROUP_KEYS, path)
        repetitions = self._count(group, "repetitions", path, repetitions)
        timeout = self._positive(group, "timeout_s", path, timeout)
        durations = t_end | self._durations(group.get("t_end", {}), _join(path, "t_end"))
        scenes = self._scenarios(group, path)
        methods = self._methods(group, path)
        steps = self._steps(group, path)
        cases = []
        for name, mech in scenes:
            duration = self._duration(durations, name, mech)
            usable = [dt for i, dt in steps
                      if self._divides(dt, duration, f"{_join(path, 'dts')}[{i}]", name)
                      and self._samples(dt, mech, f"{_join(path, 'dts')}[{i}]")]
            cases += [CaseSpec(name, adapter, method, dt, duration, repetitions, timeout)
                      for adapter, strings in methods.items() for method in strings
                      for dt in usable]
        return cases

    @staticmethod
    def _duration(durations: dict[str, float], name: str, mech: Mechanism) -> float:
        """The duration of scenario ``name`` under the overrides (never beyond its own), s."""
        return min(durations.get(name, durations.get(EVERY_SCENARIO, mech.duration)),
                   mech.duration)

    def _divides(self, dt: float, duration: float, field: str, name: str) -> bool:
        try:
            steps_in(dt, duration)
        except ValueError as error:
            self.c.add(field, f"scenario {name!r}: {error}")
            return False
        return True

    def _samples(self, dt: float, mech: Mechanism, field: str) -> bool:
        """Whether ``dt`` divides the scene's own evaluation step (``sample_step``)."""
        try:
            steps_per_sample(dt, mech.sample_step)
        except ValueError as error:
            self.c.add(field, f"scenario {mech.name!r}: {error}")
            return False
        return True

    # --- sweep --------------------------------------------------------------------------------

    def _sweep(self, table: Any, t_end: dict[str, float]) -> SweepSpec | None:
        if not isinstance(table, dict):
            self.c.add("sweep", f"expected a table, got {table!r}")
            return None
        self.c.unknown_keys(table, _SWEEP_KEYS, "sweep")
        scenes = self._scenarios(table, "sweep")
        methods = self._methods(table, "sweep")
        dt_min, dt_max = (self._step(table[key], f"sweep.{key}") if key in table
                          else self.c.required(table, key, "sweep") for key in ("dt_min", "dt_max"))
        bisections = self._count(table, "max_bisections", "sweep", 12)
        if dt_min is not None and dt_max is not None and dt_min >= dt_max:
            self.c.add("sweep.dt_min", f"must be below dt_max = {dt_max!r}, got {dt_min!r}")
        if dt_min is None or dt_max is None:
            return None
        durations = {name: self._duration(t_end, name, mech) for name, mech in scenes}
        for name, duration in durations.items():
            for key, dt in (("dt_min", dt_min), ("dt_max", dt_max)):
                self._divides(dt, duration, f"sweep.{key}", name)
        return SweepSpec(tuple(durations), tuple(methods),
                         {a: tuple(m) for a, m in methods.items()}, dt_min, dt_max, bisections,
                         durations, {name: mech.sample_step for name, mech in scenes})
