"""pyproject.toml lists the code packages by hand (the repository's harness/ and adapters/
folders, and the shipped scenarios and campaigns, are mapped into the one import package ``mbh``,
which setuptools' package finder cannot combine with): the list must name every code package, or a
wheel would silently lack one."""

import tomllib

import setuptools

from tests.helpers import ROOT

DATA_PACKAGES = {"mbh._harness.scenarios", "mbh._harness.campaigns"}


def test_every_code_package_is_listed():
    settings = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    mapped = {"harness": "mbh._harness", "adapters": "mbh._adapters", "mbh": "mbh"}
    found = {mapped[top] + name[len(top):]
             for top in mapped for name in setuptools.find_packages(str(ROOT), include=[f"{top}*"])
             if name.split(".")[0] == top}
    assert set(settings["packages"]) - DATA_PACKAGES == found
    assert set(settings["package-dir"]) == DATA_PACKAGES | {"mbh._harness", "mbh._adapters"}
    assert all(name.split(".")[0] == "mbh" for name in settings["packages"])
