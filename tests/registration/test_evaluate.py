"""evaluate(): the transformation and distance it is given are checked at the edge, by
the same shared checks as register()'s init, and named as the caller named them."""

from __future__ import annotations

import numpy as np
import pytest

from o3d_rpointhop import register
from o3d_rpointhop.datasets import make_object
from o3d_rpointhop.registration import evaluate


@pytest.fixture(scope="module")
def cloud():
    return make_object(600, shape_seed=4)


@pytest.mark.parametrize(
    "matrix, message",
    [
        (np.eye(3), "transformation must be a finite 4x4 matrix"),
        (np.full((4, 4), np.nan), "transformation must be a finite 4x4 matrix"),
        (np.diag([1.0, 1.0, -1.0, 1.0]), "transformation's upper-left 3x3 block"),
        (np.diag([2.0, 1.0, 1.0, 1.0]), "transformation's upper-left 3x3 block"),
    ],
)
def test_a_bad_transformation_is_named(cloud, matrix, message):
    with pytest.raises(ValueError, match=message):
        evaluate(cloud, cloud, matrix)


def test_a_bad_init_is_named_init(cloud):
    with pytest.raises(ValueError, match="init's upper-left 3x3 block"):
        register(cloud, cloud, global_method=None, init=np.diag([1.0, 1.0, -1.0, 1.0]))


@pytest.mark.parametrize("distance", [0.0, -1.0, np.inf, True, "0.1"])
def test_distance_must_be_a_positive_number(cloud, distance):
    with pytest.raises(ValueError, match="The .distance. parameter of evaluate must be"):
        evaluate(cloud, cloud, np.eye(4), distance=distance)


def test_one_fitness_register_and_evaluate_agree():
    """The same transformation gets the same fitness from register() and evaluate()
    (both measure at the settings' fitness_distance), in the library and on the
    command line."""
    target = make_object(1500, shape_seed=5, sample_seed=1)
    source = make_object(1500, shape_seed=5, sample_seed=2) + [0.2, 0.0, 0.0]
    result = register(source, target)
    scored = evaluate(source, target, result.transformation)
    assert scored.distance == result.distance
    assert scored.fitness == pytest.approx(result.fitness, abs=1e-12)
    assert scored.inlier_rmse == pytest.approx(result.inlier_rmse, rel=1e-9)


def test_one_fitness_on_the_command_line(tmp_path, capsys):
    import json

    from o3d_rpointhop.cli import main

    target = make_object(1500, shape_seed=5, sample_seed=1)
    source = make_object(1500, shape_seed=5, sample_seed=2) + [0.2, 0.0, 0.0]
    np.save(tmp_path / "s.npy", source)
    np.save(tmp_path / "t.npy", target)
    files = [str(tmp_path / "s.npy"), str(tmp_path / "t.npy")]
    main(["register", *files, "--transform", str(tmp_path / "T.txt"), "--json"])
    registered = json.loads(capsys.readouterr().out)
    main(["evaluate", *files, "--transform", str(tmp_path / "T.txt"), "--json"])
    evaluated = json.loads(capsys.readouterr().out)
    assert evaluated["distance"] == registered["distance"]
    assert abs(evaluated["fitness"] - registered["fitness"]) < 1e-6  # the matrix printed to 1e-10
