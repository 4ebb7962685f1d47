"""How to make a stored run's campaign run again: the campaign as ``mbh run`` takes it."""

from __future__ import annotations

import shlex
from pathlib import Path

from mbh._harness.common.locations import shipped


def campaign_argument(manifest: dict) -> str:
    """The campaign of the run of ``manifest`` as ``mbh run`` takes it, shell-quoted: its name
    when the run was made from the shipped campaign file of that name, else the file's path as
    the manifest stores it (``campaign_path``, as it was given: a relative path holds from the
    folder the run was made in)."""
    name = manifest.get("campaign", "")
    stored = manifest.get("campaign_path")
    shipped_file = shipped("campaigns") / f"{name}.toml"
    source = name if not stored or Path(stored).resolve() == shipped_file.resolve() else stored
    return shlex.quote(str(source))
