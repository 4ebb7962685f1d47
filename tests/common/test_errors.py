"""Every error class of ``harness/`` derives from :class:`mbh._harness.common.errors.MbhError`, so a
caller catches the project's errors in one ``except MbhError`` clause."""

from __future__ import annotations

import importlib
import inspect
import pkgutil

import mbh
import mbh._harness
from mbh._harness.common.errors import MbhError

#: Exception classes named "...Error" that are internal signals, not user-facing errors (none).
EXEMPT: set[str] = set()


def error_classes() -> dict[str, type]:
    """Every exception class whose name ends in "Error" defined in a module of ``harness/``."""
    found = {}
    for info in pkgutil.walk_packages(mbh._harness.__path__, prefix="mbh._harness."):
        module = importlib.import_module(info.name)
        for name, value in vars(module).items():
            if (inspect.isclass(value) and issubclass(value, BaseException)
                    and value.__module__ == module.__name__ and name.endswith("Error")):
                found[f"{module.__name__}.{name}"] = value
    return found


def test_every_harness_error_derives_from_mbh_error():
    classes = error_classes()
    assert "mbh._harness.model.scenario.ScenarioError" in classes  # the walk reached the subpackages
    strays = sorted(name for name, cls in classes.items()
                    if name not in EXEMPT and not issubclass(cls, MbhError))
    assert not strays, f"not derived from MbhError: {strays}"


def test_errors_keep_their_builtin_base():
    from mbh._harness.neutral.assembly import AssemblyError
    from mbh._harness.model.scenario import ScenarioError
    from mbh._harness.references.build import ReferenceBuildError

    assert issubclass(ScenarioError, ValueError)
    assert issubclass(AssemblyError, ValueError)
    assert issubclass(ReferenceBuildError, RuntimeError)


def test_mbh_exports_the_base_class():
    assert mbh.MbhError is MbhError
