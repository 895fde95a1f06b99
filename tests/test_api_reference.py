"""The API reference (docs/api) builds from the docstrings with warnings as errors, and
names every public name of the package: a docstring that stops parsing, or a public
name added without a page, fails here."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

import o3d_rpointhop

sphinx_build = pytest.importorskip("sphinx.cmd.build")

API = Path(__file__).resolve().parents[1] / "docs" / "api"


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore:The mapping interface for autodoc options")  # Sphinx's own
def test_the_reference_builds_without_warnings(tmp_path):
    status = sphinx_build.build_main(
        ["-b", "html", "-q", "-W", "-E", "-d", str(tmp_path / "doctrees"), str(API), str(tmp_path)]
    )
    assert status == 0
    page = (tmp_path / "registration.html").read_text()
    assert "o3d_rpointhop.Matcher" in page and "max_matches" in page


def test_every_public_name_has_an_entry():
    pages = "\n".join(p.read_text() for p in API.glob("*.rst"))
    documented = set(
        re.findall(r"\.\. auto(?:class|function):: o3d_rpointhop\.(?:\w+\.)*(\w+)", pages)
    )
    modules = set(re.findall(r"\.\. automodule:: o3d_rpointhop\.(\w+)", pages))
    exported = {name for name in o3d_rpointhop.__all__ if not name.startswith("_")}
    in_modules = {"rigid_transform", "to_open3d_feature", "to_point_cloud"}
    assert {"transforms", "open3d_interop"} <= modules
    assert exported - documented - in_modules == set()
