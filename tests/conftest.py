"""Shared fixtures: small synthetic clouds and a model fitted on them.

Everything here is generated, so the suite runs on a fresh clone. Tests that need the
real data in ``../shared/data`` use the ``shared_data`` fixture and are skipped when it
is absent.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from o3d_rpointhop import RPointHopTransformer
from o3d_rpointhop.datasets import make_blob

SHARED_DATA = Path(
    os.environ.get("O3D_RPOINTHOP_DATA", Path(__file__).resolve().parents[2] / "shared" / "data")
)


@pytest.fixture(scope="session")
def shared_data() -> Path:
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real data not found at {SHARED_DATA}")
    return SHARED_DATA


@pytest.fixture(scope="session")
def train_clouds() -> list[np.ndarray]:
    return [make_blob(384, shape_seed=s) for s in range(6)]


@pytest.fixture(scope="session")
def fitted(train_clouds) -> RPointHopTransformer:
    return RPointHopTransformer(random_state=0).fit(train_clouds)


@pytest.fixture
def cloud() -> np.ndarray:
    return make_blob(300, shape_seed=42)


def random_motion(seed: int, translation_scale: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """A random rotation matrix and translation vector."""
    rng = np.random.default_rng(seed)
    rotation = Rotation.random(random_state=seed).as_matrix()
    return rotation, rng.uniform(-1.0, 1.0, 3) * translation_scale


def relative_difference(a: np.ndarray, b: np.ndarray) -> float:
    """Largest deviation between descriptor arrays, relative to their spread.

    Measured against the largest deviation of ``a`` from its per-component mean (not
    against its magnitude, which the constant Saab bias inflates), so a small value
    really means the descriptors agree.
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    return float(np.abs(a - b).max() / np.abs(a - a.mean(axis=0)).max())
