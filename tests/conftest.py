"""Shared fixtures: small synthetic clouds and a model fitted on them.

Everything here is generated, so the suite runs on a fresh clone. Tests that need the
real data in ``../shared/data`` use the ``shared_data`` fixture and are skipped when it
is absent.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from o3d_rpointhop import RPointHopTransformer
from o3d_rpointhop.datasets import data_home, make_blob, make_object


def _data_line() -> str:
    try:
        return f"real data: {data_home()}"
    except FileNotFoundError as exc:
        return (
            f"real data: not found, the tests marked realdata were skipped ({exc}; set "
            "O3D_RPOINTHOP_DATA to point at it)"
        )


def pytest_report_header(config) -> str:
    """At the top of a verbose run: where the real data was found, or where it was
    looked for and how to point at it."""
    return _data_line()


def pytest_terminal_summary(terminalreporter, exitstatus, config) -> None:
    """Once, at the end of every run (``-q`` included), when the real data was not
    found: where it was looked for and how to point at it."""
    line = _data_line()
    if "not found" in line:
        terminalreporter.write_line(line)


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The real data folder (``data_home()``'s lookup); skips the test without it."""
    try:
        return data_home()
    except FileNotFoundError as exc:
        pytest.skip(f"real data not found: {exc}")


@pytest.fixture(scope="session")
def train_clouds() -> list[np.ndarray]:
    return [make_blob(384, shape_seed=s) for s in range(6)]


@pytest.fixture(scope="session")
def fitted(train_clouds) -> RPointHopTransformer:
    return RPointHopTransformer(random_state=0).fit(train_clouds)


@pytest.fixture
def cloud() -> np.ndarray:
    return make_blob(300, shape_seed=42)


@pytest.fixture(scope="session")
def object_model() -> RPointHopTransformer:
    """A model fitted on synthetic objects (quick, and independent of the shipped files)."""
    return RPointHopTransformer(random_state=0).fit(
        [make_object(600, shape_seed=s) for s in range(8)]
    )


@pytest.fixture(scope="session")
def pretrained32() -> RPointHopTransformer:
    """The shipped ModelNet40 model on 32 axes."""
    return RPointHopTransformer.pretrained(n_components=32)


@pytest.fixture(scope="session")
def object_target() -> np.ndarray:
    return make_object(800, shape_seed=321)


@pytest.fixture(scope="session")
def shapes() -> np.ndarray:
    """Three ModelNet40-sized objects of 2048 points."""
    return np.stack([make_object(2048, shape_seed=s) for s in range(3)])
