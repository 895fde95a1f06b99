"""make_room: one room, sampled by ``random_state``."""

from __future__ import annotations

import numpy as np
import pytest

from o3d_rpointhop.datasets import make_room


def test_make_room_random_state_picks_the_points_of_one_room():
    a, b = make_room(500, random_state=1), make_room(500, random_state=2)
    assert a.shape == b.shape == (500, 3)
    assert not np.array_equal(a, b)
    # The same room: both samplings span the same box.
    np.testing.assert_allclose(a.min(axis=0), b.min(axis=0), atol=0.1)
    np.testing.assert_allclose(a.max(axis=0), b.max(axis=0), atol=0.1)


def test_make_room_seed_is_the_former_name_of_random_state():
    with pytest.warns(FutureWarning, match="make_room"):
        old = make_room(300, seed=4)
    np.testing.assert_array_equal(old, make_room(300, random_state=4))
