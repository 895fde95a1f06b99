"""Flags and warnings: planar, float32 at survey scale, no overlap, symmetric shapes."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import OBJECT, TURN

from o3d_rpointhop import RegistrationWarning, register
from o3d_rpointhop.datasets import make_object


def test_float32_at_survey_scale_warns_about_precision(pretrained32):
    far = (OBJECT * 10 + [512345.0, 4123456.0, 87.0]).astype(np.float32)
    with pytest.warns(RegistrationWarning, match="float32 resolves only"):
        register(far, far, pretrained32)


def test_planar_cloud_warns_and_no_overlap_is_flagged(pretrained32):
    rng = np.random.default_rng(0)
    plane = np.c_[rng.uniform(size=(800, 2)), np.zeros(800)]
    with pytest.warns(RegistrationWarning, match="planar"):
        register(plane, plane @ TURN.T, pretrained32)
    other = make_object(1024, shape_seed=30, sample_seed=1)  # a different object
    with pytest.warns(RegistrationWarning, match="did not converge"):
        result = register(other, OBJECT, pretrained32)
    assert not result.converged


def test_symmetric_shape_is_flagged_ambiguous(pretrained32):
    from o3d_rpointhop.datasets.synthetic import _box_surface

    rng = np.random.default_rng(1)
    box = _box_surface(rng, 1500, np.array([1.0, 0.6, 0.3]))
    other = _box_surface(rng, 1500, np.array([1.0, 0.6, 0.3]))
    with pytest.warns(RegistrationWarning, match="ambiguous"):
        result = register(other, box, pretrained32)
    assert result.converged and result.ambiguous
