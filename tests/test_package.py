"""The package as installed: importable under python -OO."""

from __future__ import annotations

import pytest


def test_import_works_under_python_OO():
    import subprocess
    import sys

    done = subprocess.run(
        [sys.executable, "-OO", "-c", "import o3d_rpointhop; print('ok')"],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr


@pytest.mark.slow
def test_the_package_top_loads_lazily_and_exports_everything():
    """``import o3d_rpointhop`` loads neither Open3D nor scikit-learn; every name in
    ``__all__`` resolves, and the CLI's copy of the shipped model names is right."""
    import subprocess
    import sys

    code = (
        "import sys, o3d_rpointhop as o; "
        "print(any(m in sys.modules for m in ('open3d', 'sklearn'))); "
        "print(all(getattr(o, n) is not None for n in o.__all__)); "
        "print('open3d' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "True", "True"]
    from o3d_rpointhop.cli._common import SHIPPED_MODELS
    from o3d_rpointhop.descriptors import PRETRAINED_MODELS

    assert SHIPPED_MODELS == tuple(PRETRAINED_MODELS)
    from o3d_rpointhop.cli._common import POSE_FORMATS
    from o3d_rpointhop.poses import POSE_FORMATS as LIBRARY_POSE_FORMATS

    assert POSE_FORMATS == LIBRARY_POSE_FORMATS


def test_help_builds_no_command_in_full():
    """``o3d-rpointhop --help`` lists every command without loading the library."""
    import subprocess
    import sys

    code = (
        "import sys; from o3d_rpointhop.cli import main\n"
        "try:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
        "print('LOADED', any(m in sys.modules for m in ('open3d', 'sklearn')))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert "LOADED False" in out.stdout
    for command in ("register", "evaluate", "view", "config", "reconstruct", "benchmark"):
        assert command in out.stdout
