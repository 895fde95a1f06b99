"""Type checkers see the public API typed (``py.typed`` ships): mypy on a small user
script infers the results of ``register()``, ``register_multiway()`` and
``evaluate()``, and catches a misspelt attribute on them."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

USER_SCRIPT = """
import numpy as np
from o3d_rpointhop import RPointHopTransformer, evaluate, register, register_multiway

cloud = np.zeros((100, 3))
result = register(cloud, cloud, RPointHopTransformer.pretrained("object"))
reveal_type(result)
reveal_type(register_multiway([cloud, cloud]))
reveal_type(evaluate(cloud, cloud, np.eye(4)))
reveal_type(RPointHopTransformer.pretrained().transform(cloud))
fitness: float = result.fitness
"""


@pytest.mark.slow
def test_mypy_sees_the_public_api_typed(tmp_path):
    pytest.importorskip("mypy")
    script = tmp_path / "user.py"
    script.write_text(USER_SCRIPT + "result.fitnes\n")
    env = {**os.environ, "MYPYPATH": str(ROOT)}
    run = subprocess.run(
        [
            sys.executable,
            "-m",
            "mypy",
            "--follow-imports=silent",
            "--no-incremental",
            "--cache-dir",
            str(tmp_path / "cache"),
            str(script),
        ],
        capture_output=True,
        text=True,
        env=env,
        cwd=tmp_path,
        timeout=600,
    )
    out = run.stdout
    assert 'Revealed type is "o3d_rpointhop.registration.result.RegistrationResult"' in out
    assert 'Revealed type is "o3d_rpointhop.registration.result.MultiwayResult"' in out
    assert out.count("registration.result.RegistrationResult") >= 2  # evaluate() too
    assert '"RegistrationResult" has no attribute "fitnes"' in out
    assert out.count("error:") == 1, out  # the misspelling, nothing else
