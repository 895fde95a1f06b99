"""The rooms benchmark: scoring reconstructions on ground-truth pairs, and its tables."""

import numpy as np
import pytest
from helpers import synthetic_scene

from o3d_rpointhop.evaluation.rooms import (
    ROOM_METHODS,
    markdown,
    pairs_registered,
    run_rooms,
    timings_markdown,
)


def _moved(angle_deg: float, shift) -> np.ndarray:
    c, s = np.cos(np.radians(angle_deg)), np.sin(np.radians(angle_deg))
    matrix = np.eye(4)
    matrix[:2, :2] = [[c, -s], [s, c]]
    matrix[:3, 3] = shift
    return matrix


def test_pairs_registered_applies_the_official_test():
    """A pair counts when the relative pose of its fragments is within 0.2 m RMSE of
    the truth (gt.info's), not when the fragments' poses are right on their own."""
    truth_01 = _moved(30, [1.0, 0.0, 0.0])
    information = np.eye(6)
    truth = {(0, 1): (truth_01, information), (0, 2): (np.eye(4), information)}
    frame = _moved(-70, [5.0, 2.0, 0.0])  # poses in another scan's frame: still right
    poses = {0: frame, 1: frame @ truth_01, 2: frame @ _moved(0, [0.5, 0.0, 0.0])}
    assert pairs_registered(poses, truth) == 1  # (0, 2) is 0.5 m off
    poses[2] = frame
    assert pairs_registered(poses, truth) == 2
    poses[1] = None  # not placed: not registered
    assert pairs_registered(poses, truth) == 1


def _results():
    row = {"gt_pairs_registered": 3, "placed_with_pairs": 4, "placed": 4, "seconds": 10.0}
    recipe = {**row, "gt_pairs_registered": 1, "seconds": 20.0}
    return {
        "settings": {"recall_rmse": 0.2, "methods": {m: ROOM_METHODS[m] for m in ROOM_METHODS}},
        "scenes": {
            "kitchen": {
                "split": "training",
                "fragments": 5,
                "gt_pairs": 4,
                "fragments_with_pairs": 4,
                "methods": {
                    "auto": {**row, "model": "scene"},
                    "fpfh": row,
                    "open3d-recipe": recipe,
                },
            },
            "study": {
                "split": "heldout",
                "fragments": 4,
                "gt_pairs": 2,
                "fragments_with_pairs": 3,
                "methods": {
                    "auto": {**row, "gt_pairs_registered": 2},
                    "fpfh": row,
                    "open3d-recipe": recipe,
                },
            },
        },
    }


def test_tables_keep_training_and_heldout_scenes_apart():
    text = markdown(_results())
    training, heldout = text.split("## Training scenes")[1].split("## Held-out scenes")
    assert "kitchen (auto: scene)" in training and "study" not in training
    assert "study" in heldout and "kitchen" not in heldout
    assert "3 / 4 (75 %)" in training and "1 / 4 (25 %)" in training
    assert "2 / 2 (100 %)" in heldout
    times = timings_markdown(_results())
    assert "10.0 (0.50x)" in times and "20.0 (1.00x)" in times


def test_unknown_methods_and_scenes_are_refused(tmp_path):
    with pytest.raises(ValueError, match="unknown room methods"):
        run_rooms(methods=("magic",), data=tmp_path)
    (tmp_path / "3dmatch" / "fragments" / "a-scene").mkdir(parents=True)
    with pytest.raises(ValueError, match="no 3DMatch scene matches"):
        run_rooms(["kitchen"], data=tmp_path)


def test_a_synthetic_room_is_rebuilt_and_scored(tmp_path):
    """run_rooms end to end on a 3DMatch-style folder of three views: both gt pairs
    registered, every fragment placed, none of them beyond an edge no loop checks (the
    three views overlap pairwise: a loop)."""
    synthetic_scene(tmp_path, "room", ids=(0, 4, 10), seed=5)
    lines = []
    out = run_rooms(methods=("auto",), data=tmp_path, n_jobs=1, log=lines.append)
    row = out["scenes"]["room"]["methods"]["auto"]
    assert out["scenes"]["room"]["gt_pairs"] == 2
    assert (row["gt_pairs_registered"], row["placed_with_pairs"], row["placed"]) == (2, 3, 3)
    assert row["unverified"] == 0 and len(lines) == 1
