"""pyproject.toml lists the code packages by hand (the shipped scenarios and campaigns are mapped
data packages, which setuptools' package finder cannot combine with): the list must name every
code package, or a wheel would silently lack one."""

import tomllib

import setuptools

from tests.helpers import ROOT

DATA_PACKAGES = {"harness.scenarios", "harness.campaigns"}


def test_every_code_package_is_listed():
    settings = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    found = set(setuptools.find_packages(str(ROOT), include=["harness*", "adapters*", "mbh*"]))
    assert set(settings["packages"]) - DATA_PACKAGES == found
    assert set(settings["package-dir"]) == DATA_PACKAGES
