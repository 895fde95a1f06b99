"""The package as installed: importable under python -OO."""

from __future__ import annotations


def test_import_works_under_python_OO():
    import subprocess
    import sys

    done = subprocess.run(
        [sys.executable, "-OO", "-c", "import o3d_rpointhop; print('ok')"],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr
