"""Where the harness finds what it ships and where it writes what it makes.

Shipped files (read only):

* ``scenarios`` (the scenario files and, in ``scenarios/references``, their verified references)
  and ``campaigns`` (the campaign files).  In a checkout they are the repository's folders of those
  names; an installed wheel carries them inside the ``harness`` package (``harness/scenarios``,
  ``harness/campaigns``: ``pyproject.toml`` maps the folders there), read through
  :mod:`importlib.resources`.

Written files, never inside the installed package:

* the user cache (:func:`user_cache`): references of scenes that are not shipped, generated
  functions (:func:`generated_cache`) and compiled kernels (:mod:`mbh._harness.common.kernel_cache`);
  ``$MBH_CACHE_HOME``, else the platform's cache folder for ``mbh`` (``$XDG_CACHE_HOME/mbh`` or
  ``~/.cache/mbh`` on Linux, via :mod:`platformdirs`);
* the results root (:func:`mbh._harness.store.runs.results_root`): ``$MBH_RESULTS_DIR``, else
  ``results/`` in a checkout, else the platform's data folder for ``mbh`` (``~/.local/share/mbh``
  on Linux).
"""

from __future__ import annotations

import importlib.resources
import os
from pathlib import Path

import platformdirs

#: Environment variable moving the whole user cache.
CACHE_ENV = "MBH_CACHE_HOME"
#: Environment variable moving the generated functions alone.
GENERATED_ENV = "MBH_GENERATED_DIR"
#: The folders shipped with the harness.
SHIPPED = ("scenarios", "campaigns")

#: The harness's code: the repository's harness/ in a checkout, mbh/_harness in an installed wheel
#: (pyproject.toml maps the folder into the one import package).
HARNESS_FOLDER = Path(__file__).resolve().parents[1]
#: The adapters' code beside it: adapters/ in a checkout, mbh/_adapters in a wheel.
ADAPTERS_FOLDER = HARNESS_FOLDER.parent / ("adapters" if HARNESS_FOLDER.name == "harness"
                                           else "_adapters")
#: The folder holding both: the checkout, or the installed mbh package.
CODE_ROOT = HARNESS_FOLDER.parent


def checkout() -> Path | None:
    """The repository the harness runs from (a checkout or an editable install), or None for an
    installed wheel: the folder holding ``pyproject.toml`` beside the ``harness`` folder."""
    return CODE_ROOT if (CODE_ROOT / "pyproject.toml").is_file() else None


def shipped(folder: str) -> Path:
    """The shipped folder ``folder`` (one of :data:`SHIPPED`): inside the installed package, else
    the checkout's folder of that name."""
    if folder not in SHIPPED:
        raise ValueError(f"{folder!r} is not a shipped folder ({', '.join(SHIPPED)})")
    packaged = Path(str(importlib.resources.files("mbh._harness") / folder))
    if packaged.is_dir():
        return packaged
    return CODE_ROOT / folder


def user_cache() -> Path:
    """The user cache folder: ``$MBH_CACHE_HOME``, else the platform's user cache folder."""
    configured = os.environ.get(CACHE_ENV)
    return Path(configured) if configured else platformdirs.user_cache_path("mbh")


def generated_cache() -> Path:
    """The folder of the generated functions (:mod:`mbh._adapters.inhouse.codegen.generated`):
    ``$MBH_GENERATED_DIR``, else ``generated`` in :func:`user_cache`."""
    configured = os.environ.get(GENERATED_ENV)
    return Path(configured) if configured else user_cache() / "generated"


def user_data() -> Path:
    """The platform's user data folder for ``mbh`` (results of an installed harness)."""
    return platformdirs.user_data_path("mbh")
