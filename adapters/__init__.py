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
"""

from __future__ import annotations

import importlib
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


def _discover() -> tuple[dict[str, Registration], list[tuple[Registration, str]]]:
    """(registered adapters by name, [(ignored entry point, why)]) from the built-ins and the
    installed entry points, distributions in name order."""
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


def version_or_problem(name: str) -> tuple[str | None, str]:
    """(adapter ``name``'s ``version()``, ``""``), or (None, why) when the adapter cannot be
    loaded or its ``version()`` raises; the reason names the adapter and its package."""
    try:
        adapter = get_adapter(name)
    except AdapterLoadError as error:
        return None, str(error)
    try:
        return adapter.version(), ""
    except Exception as error:  # noqa: BLE001 — a broken adapter is reported, not fatal
        return None, blame(registration(name).label, "version()", error)


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
