"""Sphinx configuration of the API reference: every page is built from the package's
numpydoc docstrings (``sphinx.ext.napoleon`` reads their sections).

Build: ``python -m sphinx -b html docs/api build/api`` (``tests/test_api_reference.py``
builds it with warnings as errors, so a docstring that no longer parses fails the suite).
"""

from importlib.metadata import version as _version

project = "o3d-rpointhop"
author = "o3d-rpointhop developers"
release = _version("o3d-rpointhop")
extensions = ["sphinx.ext.autodoc", "sphinx.ext.napoleon"]
napoleon_google_docstring = False
napoleon_numpy_docstring = True
napoleon_use_rtype = False
# Attributes as fields of their class (autodoc documents the members themselves).
napoleon_use_ivar = True
# Parameters as one field list with their numpydoc types as written (the types are
# prose, "array-like (n, 3) or Open3D point cloud", not names to cross-reference).
napoleon_use_param = False
autodoc_member_order = "bysource"
autodoc_typehints = "none"  # the numpydoc sections give the types
# scikit-learn's metadata-routing setters are generated on every estimator: theirs.
autodoc_default_options = {
    "members": True,
    "undoc-members": False,
    "exclude-members": "set_fit_request, set_transform_request, set_score_request, "
    "set_output, get_metadata_routing",
}
html_theme = "alabaster"
html_static_path: list[str] = []
exclude_patterns = ["_build"]
