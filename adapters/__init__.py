"""Adapter registry: engine name → adapter class, imported on first use.

Two sources register adapters: the built-in engines (:data:`BUILT_IN`) and every installed
distribution that declares an entry point in the group :data:`ENTRY_POINT_GROUP`
(``mbh.adapters``, value ``module:Class``; docs/adapter-contract.md).  A built-in name wins a
clash, and among third-party entry points the first distribution in name order does; every entry
point left out is reported (:func:`ignored` and a :class:`AdapterClashWarning`), never dropped
silently.

Discovery reads installed metadata only: engines are imported lazily, so that listing adapters or
running one engine never pays for (or fails on) another engine's import.  An adapter that cannot
be loaded raises :class:`AdapterLoadError` naming the adapter and the package that provides it.

A solver need not be registered to run: :func:`resolve_adapter` takes an adapter name, an
:class:`~mbh._adapters.base.Adapter` subclass or an instance of one, and gives the adapter a case
runs with, named and attributed exactly as a registered one (a class some installed package
declares takes that registration's name and package; any other class runs under its own
``name``, with no package).
"""

from __future__ import annotations

import copy
import importlib
import os
import sys
import warnings
from dataclasses import dataclass
from importlib.metadata import entry_points

from mbh._adapters.base import Adapter, adapter_label, blame, describe
from mbh._harness.common.errors import MbhError

#: Entry-point group a third-party package declares its adapters in (value ``module:Class``).
ENTRY_POINT_GROUP = "mbh.adapters"
#: The ``origin`` of a built-in adapter.
BUILT_IN_ORIGIN = "built-in"
#: The engines that ship with the harness: name → ``module:Class``.
BUILT_IN = {
    "inhouse": "mbh._adapters.inhouse.adapter:InhouseAdapter",
    "mujoco": "mbh._adapters.mujoco_adapter:MujocoAdapter",
    "pybullet": "mbh._adapters.pybullet_adapter:PybulletAdapter",
    "pinocchio": "mbh._adapters.pinocchio_adapter:PinocchioAdapter",
    "exudyn": "mbh._adapters.exudyn_adapter:ExudynAdapter",
}


class UnknownAdapterError(MbhError, ValueError):
    """No adapter of that name is registered; the message lists the registered ones."""


class AdapterLoadError(MbhError, ImportError):
    """A registered adapter cannot be loaded (its module fails to import, its class is missing, is
    not an :class:`~mbh._adapters.base.Adapter` or fails to construct); the message names the adapter,
    the package that provides it and the error."""


class AdapterChoiceError(MbhError, ValueError):
    """An adapter given as a class or an instance that cannot stand for one: not an
    :class:`~mbh._adapters.base.Adapter`, without a ``name``, or named like another registered
    adapter; the message says which and what to change."""


class AdapterClashWarning(UserWarning):
    """An entry point of :data:`ENTRY_POINT_GROUP` is ignored: its name is already registered."""


@dataclass(frozen=True)
class Registration:
    """Where an adapter comes from.

    Attributes
    ----------
    name : str
        Registry name (campaign files, ``--adapter``, the rows' ``adapter`` column).
    target : str
        ``module:Class`` of the adapter class.
    origin : str
        :data:`BUILT_IN_ORIGIN`, or the name of the distribution that declares the entry point.
    package_version : str or None
        That distribution's version; None for a built-in adapter.
    """

    name: str
    target: str
    origin: str = BUILT_IN_ORIGIN
    package_version: str | None = None

    @property
    def built_in(self) -> bool:
        return self.origin == BUILT_IN_ORIGIN

    @property
    def package(self) -> str:
        """``"NAME VERSION"`` of the providing distribution; ``""`` for a built-in adapter."""
        return "" if self.built_in else f"{self.origin} {self.package_version}"

    @property
    def label(self) -> str:
        """``adapter 'toy' from package mbh-toy-adapter 0.1.0`` (or ``(built-in)``)."""
        return adapter_label(self.name, self.package)


#: (the state of ``sys.path``'s folders, what :func:`_discover` found there) of the last discovery.
_DISCOVERED: list[tuple] = []


def _path_state() -> tuple:
    """Each ``sys.path`` entry with its modification time (ns; None if absent): a distribution
    installed into or removed from a folder changes the folder's time."""
    state = []
    for entry in sys.path:
        try:
            state.append((entry, os.stat(entry or ".").st_mtime_ns))
        except OSError:
            state.append((entry, None))
    return tuple(state)


def _discover() -> tuple[dict[str, Registration], list[tuple[Registration, str]]]:
    """(registered adapters by name, [(ignored entry point, why)]) from the built-ins and the
    installed entry points, distributions in name order.  Kept while no folder of ``sys.path``
    changes: reading the installed metadata took ~9 ms, in every case of a campaign (whose
    processes, forked from the warm template, find the template's discovery)."""
    state = _path_state()
    if not _DISCOVERED or _DISCOVERED[0] != state:
        _DISCOVERED[:] = [state, _read_entry_points()]
    found, left_out = _DISCOVERED[1]
    return dict(found), list(left_out)


def _read_entry_points() -> tuple[dict[str, Registration], list[tuple[Registration, str]]]:
    """:func:`_discover`'s answer, read from the installed metadata."""
    found = {name: Registration(name, target) for name, target in BUILT_IN.items()}
    left_out = []
    points = sorted(entry_points(group=ENTRY_POINT_GROUP),
                    key=lambda point: (_distribution(point)[0], point.name))
    for point in points:
        registration = Registration(point.name, point.value, *_distribution(point))
        if point.name in found:
            left_out.append((registration, f"{registration.label} is ignored: the name belongs "
                                           f"to the {found[point.name].label}"))
        else:
            found[point.name] = registration
    return found, left_out


def _distribution(point) -> tuple[str, str]:
    """(name, version) of the distribution declaring entry point ``point``."""
    dist = point.dist
    return (dist.name, dist.version) if dist is not None else ("unknown package", "?")


def registrations() -> dict[str, Registration]:
    """Every registered adapter by name, built-ins first; warns
    (:class:`AdapterClashWarning`) for each entry point left out."""
    found, left_out = _discover()
    for _, why in left_out:
        warnings.warn(why, AdapterClashWarning, stacklevel=2)
    return found


def ignored() -> list[tuple[Registration, str]]:
    """The entry points left out of the registry, each with the sentence saying why."""
    return _discover()[1]


def adapter_names() -> list[str]:
    """Registered adapter names: the built-in ones, then the installed third-party ones."""
    return list(registrations())


def registration(name: str) -> Registration:
    """Where adapter ``name`` comes from; raises :class:`UnknownAdapterError` listing the
    registered names."""
    found = registrations()
    if name not in found:
        raise UnknownAdapterError(f"unknown adapter {name!r}; valid: {', '.join(found)}")
    return found[name]


def get_adapter(name: str) -> Adapter:
    """An instance of adapter ``name``, with ``name`` and ``package`` set from its registration.

    Raises
    ------
    UnknownAdapterError
        For a name that is not registered (a ValueError).
    AdapterLoadError
        When the adapter cannot be loaded (an ImportError naming the adapter and its package).
    """
    found = registration(name)
    module_name, _, class_name = found.target.partition(":")
    try:
        cls = getattr(importlib.import_module(module_name), class_name)
        if not (isinstance(cls, type) and issubclass(cls, Adapter)):
            raise TypeError(f"{found.target} is not a subclass of mbh._adapters.base.Adapter")
        adapter = cls()
    except Exception as error:  # noqa: BLE001 — any failure of third-party code is named
        raise AdapterLoadError(f"{found.label} cannot be loaded ({found.target}): "
                               f"{describe(error)}") from error
    adapter.name, adapter.package = name, found.package
    return adapter


def class_path(cls: type) -> str:
    """``module:QualifiedName`` of a class, as an entry point names it."""
    return f"{cls.__module__}:{cls.__qualname__}"


def _registration_of(cls: type) -> Registration | None:
    """The registration whose target is ``cls`` (its module already imported), or None."""
    for found in _discover()[0].values():
        module_name, _, attribute = found.target.partition(":")
        module = sys.modules.get(module_name)
        if module is not None and getattr(module, attribute, None) is cls:
            return found
    return None


def resolve_adapter(adapter: str | type[Adapter] | Adapter) -> Adapter:
    """The adapter a case runs with, from a registered name, an Adapter subclass or an instance.

    A name gives :func:`get_adapter`'s adapter.  A class is instantiated (no arguments); an
    instance is used as it is (a shallow copy when its ``name`` or ``package`` must be set).  A
    class that an entry point or the built-ins register takes that registration's name and
    package, so its rows equal the registered adapter's; any other class runs under its own
    ``name`` attribute with no package.

    Raises
    ------
    UnknownAdapterError
        For a name that is not registered.
    AdapterLoadError
        When a registered adapter cannot be loaded, or a class fails to construct.
    AdapterChoiceError
        For anything else that is not an adapter, an adapter without a ``name``, or an
        unregistered class named like a registered adapter.
    """
    if isinstance(adapter, str):
        return get_adapter(adapter)
    cls = adapter if isinstance(adapter, type) else type(adapter)
    if not issubclass(cls, Adapter):
        raise AdapterChoiceError(f"expected an adapter name, an Adapter subclass or an instance "
                                 f"of one, got {adapter!r}")
    found = _registration_of(cls)
    name, package = (found.name, found.package) if found else (adapter.name, "")
    if not found:
        _check_own_name(cls, name)
    if isinstance(adapter, type):
        try:
            instance = cls()
        except Exception as error:  # noqa: BLE001 — the adapter's own code: named
            raise AdapterLoadError(f"adapter class {class_path(cls)} cannot be constructed: "
                                   f"{describe(error)}") from error
    elif (adapter.name, adapter.package) == (name, package):
        return adapter
    else:
        instance = copy.copy(adapter)
    instance.name, instance.package = name, package
    return instance


def _check_own_name(cls: type, name) -> None:
    """Raise :class:`AdapterChoiceError` unless ``name`` can name the unregistered ``cls``."""
    if not isinstance(name, str) or not name:
        raise AdapterChoiceError(f"adapter class {class_path(cls)} has no name: set its class "
                                 f"attribute `name` (it names the adapter in rows and campaign "
                                 f"files)")
    taken = _discover()[0].get(name)
    if taken is not None:
        raise AdapterChoiceError(f"adapter class {class_path(cls)} is named {name!r}, the name "
                                 f"of the registered {taken.label}; give the class another name")


def adapter_source(adapter: Adapter) -> str:
    """Names ``adapter`` in a reason: its registration's label, or for an unregistered class
    ``adapter 'mine' (class my_solver:MyAdapter)``."""
    found = _registration_of(type(adapter))
    return found.label if found else f"adapter {adapter.name!r} (class {class_path(type(adapter))})"


def version_or_problem(adapter: str | type[Adapter] | Adapter) -> tuple[str | None, str]:
    """(the adapter's ``version()``, ``""``), or (None, why) when the adapter cannot be loaded
    or its ``version()`` raises; the reason names the adapter and its package.  ``adapter`` is
    anything :func:`resolve_adapter` takes."""
    try:
        resolved = resolve_adapter(adapter)
    except AdapterLoadError as error:
        return None, str(error)
    try:
        return resolved.version(), ""
    except Exception as error:  # noqa: BLE001 — a broken adapter is reported, not fatal
        return None, blame(adapter_source(resolved), "version()", error)


def inventory() -> list[dict]:
    """One row per registered adapter, then one per ignored entry point, for ``mbh adapters``.

    Loads every registered adapter (engines are imported).  Row keys: ``name``, ``origin``
    (:data:`BUILT_IN_ORIGIN` or the distribution name), ``package_version`` (None for a built-in),
    ``version`` (the adapter's ``version()``; None when it cannot be had), ``methods`` (how
    many; None likewise) and ``problem`` (``""``, or why the adapter cannot be used).
    """
    rows = []
    for found in registrations().values():
        version, problem = version_or_problem(found.name)
        methods = None
        if not problem:
            try:
                methods = len(get_adapter(found.name).methods())
            except Exception as error:  # noqa: BLE001 — a broken adapter is listed, not fatal
                problem = blame(found.label, "methods()", error)
        rows.append({"name": found.name, "origin": found.origin,
                     "package_version": found.package_version, "version": version,
                     "methods": methods, "problem": problem})
    return rows + [{"name": left.name, "origin": left.origin,
                    "package_version": left.package_version, "version": None, "methods": None,
                    "problem": why} for left, why in ignored()]
