"""``--model auto`` (the default of register and reconstruct): the model chosen from the
clouds, said in the outputs, overridden by ``--model`` and ``--viewpoints``."""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers import write_points

from o3d_rpointhop.cli import main
from o3d_rpointhop.datasets import make_object, make_room

SENSOR = np.array([4.5, 3.5, 1.6])


@pytest.fixture()
def rooms(tmp_path):
    """Two scans of a room corner, each in its sensor's frame."""
    a, b = tmp_path / "a.ply", tmp_path / "b.ply"
    write_points(a, make_room(3000, random_state=0) - SENSOR)
    write_points(b, make_room(3000, random_state=1) - SENSOR - [0.1, 0.0, 0.05])
    return str(a), str(b)


def _register(args, capsys) -> dict:
    assert main(["register", *args, "--json"]) in (0, 3)
    return json.loads(capsys.readouterr().out)


def test_register_chooses_the_scene_model_for_room_scans(rooms, capsys):
    summary = _register(rooms, capsys)
    assert summary["model"]["model"] == "scene" and summary["model"]["viewpoints"] == "origin"
    record = summary["provenance"]
    assert record["descriptor"]["model"] == "scene"
    assert record["config"]["register"]["viewpoints"] == "origin"
    assert record["config"]["register"]["global_method"] == "consensus"  # the model's step


def test_model_and_viewpoints_flags_override_the_choice(rooms, capsys):
    named = _register([*rooms, "--model", "object"], capsys)
    assert named["model"] is None and named["provenance"]["descriptor"]["model"] == "object"
    assert named["provenance"]["config"]["register"]["viewpoints"] == "none"
    blind = _register([*rooms, "--viewpoints", "none"], capsys)
    assert blind["model"]["model"] == "scene" and blind["model"]["viewpoints"] is None
    assert blind["provenance"]["config"]["register"]["viewpoints"] == "none"


def test_register_chooses_the_object_model_for_objects(tmp_path, capsys):
    cloud = make_object(1024)
    write_points(tmp_path / "s.ply", cloud + [0.1, 0.0, 0.0])
    write_points(tmp_path / "t.ply", cloud)
    summary = _register([str(tmp_path / "s.ply"), str(tmp_path / "t.ply")], capsys)
    assert summary["model"]["model"] == "object"
    assert summary["provenance"]["descriptor"]["model"] == "object"
    assert summary["provenance"]["config"]["register"]["global_method"] == "ransac"


@pytest.mark.slow
def test_config_from_a_record_repeats_the_choice(rooms, tmp_path, capsys):
    result = tmp_path / "r.json"
    assert main(["register", *rooms, "--transform", str(result)]) in (0, 3)
    first = json.loads(result.read_text())
    capsys.readouterr()
    toml = tmp_path / "c.toml"
    assert main(["config", "--from", str(result), "-o", str(toml)]) == 0
    again = tmp_path / "again.json"
    assert main(["register", *rooms, "--config", str(toml), "--transform", str(again)]) in (0, 3)
    second = json.loads(again.read_text())
    assert np.array_equal(first["transformation"], second["transformation"])


def test_auto_is_refused_where_no_model_is_chosen(rooms, tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["describe", rooms[0], "-o", str(tmp_path / "d.npy"), "--viewpoints", "auto"])
    assert main(["describe", rooms[0], "-o", str(tmp_path / "d.npy"), "--model", "auto"]) == 2
    assert "--model auto" in capsys.readouterr().err
    settings = ["--set", "descriptor.n_components=8"]
    assert main(["register", *rooms, "--model", "auto", *settings]) == 2
    assert "--n-components applies to a named model" in capsys.readouterr().err


def test_reconstruct_describes_rooms_on_the_screening_axes(rooms, tmp_path, monkeypatch):
    """``reconstruct`` with the model left to it rebuilds rooms as
    ``register_multiway(scans)`` does: with ``SCREENING_AXES`` set, the scene model on
    that many axes, said in the poses file."""
    from o3d_rpointhop.registration import multiway

    monkeypatch.setattr(multiway, "SCREENING_AXES", {"scene": 32})
    poses = tmp_path / "poses.json"
    out = ["-o", str(tmp_path / "room.ply"), "--poses", str(poses)]
    assert main(["reconstruct", *rooms, *out, "--n-jobs", "1"]) in (0, 3)
    model = json.loads(poses.read_text())["model"]
    assert model["model"] == "scene" and model["axes"] == 32
