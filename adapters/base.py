"""The adapter contract every engine implements, the in-house formulation included.

``build(mechanism)`` → engine model; ``simulate(model, method, dt, t_end, sample_times)`` →
:class:`~harness.trajectory.Trajectory`; ``methods()`` lists the engine's methods with their
parameters; ``version()`` names the engine version.  Method names are user-facing strings
``NAME[:key=value,...]`` parsed by :func:`parse_method`.
"""

from __future__ import annotations

import abc
from dataclasses import dataclass, field

import numpy as np

from harness.model import Mechanism
from harness.trajectory import Trajectory


class UnsupportedCase(Exception):
    """Raised by ``build`` when the engine cannot represent the mechanism; the message says why."""


@dataclass(frozen=True)
class MethodSpec:
    """One method an adapter offers.

    ``params`` maps each parameter name to its default value; ``description`` says what it is.
    """

    name: str
    description: str
    params: dict = field(default_factory=dict)

    def resolve(self, given: dict) -> dict:
        """Defaults overridden by ``given``; unknown keys raise a ValueError naming the valid ones."""
        unknown = sorted(set(given) - set(self.params))
        if unknown:
            valid = ", ".join(sorted(self.params)) or "none"
            raise ValueError(f"method {self.name!r} has no parameter {', '.join(unknown)} "
                             f"(valid: {valid})")
        resolved = dict(self.params)
        for key, value in given.items():
            default = self.params[key]
            resolved[key] = _coerce(key, value, default)
        return resolved


def _coerce(key: str, value: str, default):
    if isinstance(default, bool):
        if value.lower() in ("1", "true", "yes", "on"):
            return True
        if value.lower() in ("0", "false", "no", "off"):
            return False
        raise ValueError(f"parameter {key!r} expects true/false, got {value!r}")
    if isinstance(default, (int, float)) and not isinstance(default, bool):
        try:
            number = float(value)
        except ValueError:
            raise ValueError(f"parameter {key!r} expects a number, got {value!r}") from None
        return int(number) if isinstance(default, int) and number.is_integer() else number
    return value


def parse_method(text: str) -> tuple[str, dict]:
    """Split ``"NAME:key=value,key=value"`` into ``(NAME, {key: value})`` (values as strings)."""
    name, _, rest = text.partition(":")
    params = {}
    for item in filter(None, (part.strip() for part in rest.split(","))):
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise ValueError(f"method {text!r}: expected key=value, got {item!r}")
        params[key.strip()] = value.strip()
    if not name.strip():
        raise ValueError(f"method {text!r}: empty method name")
    return name.strip(), params


class Adapter(abc.ABC):
    """Base class of every engine adapter (registered by name in :mod:`adapters`)."""

    name: str = ""

    @abc.abstractmethod
    def version(self) -> str:
        """Engine name and version, e.g. ``"mujoco 4.0.0"``."""

    @abc.abstractmethod
    def methods(self) -> list[MethodSpec]:
        """Every method, including ``default`` and ``best``."""

    @abc.abstractmethod
    def build(self, mechanism: Mechanism):
        """Engine model of ``mechanism``; raises :class:`UnsupportedCase` with a reason."""

    @abc.abstractmethod
    def simulate(self, model, method: str, dt: float, t_end: float,
                 sample_times: np.ndarray) -> Trajectory:
        """Run from the harness's assembled state; failures are a status, never an exception."""

    def method_spec(self, method: str) -> tuple[MethodSpec, dict]:
        """Look up ``method`` and resolve its parameters; unknown names list the valid ones."""
        name, given = parse_method(method)
        specs = {spec.name: spec for spec in self.methods()}
        if name not in specs:
            raise ValueError(f"unknown {self.name} method {name!r}; valid: {', '.join(specs)}")
        return specs[name], specs[name].resolve(given)
