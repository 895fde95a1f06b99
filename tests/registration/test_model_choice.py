"""The automatic model choice: the scene model for rooms scanned from their origin, the
object model for the rest, overridable, and said in the result."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from o3d_rpointhop import RPointHopTransformer, register, register_multiway
from o3d_rpointhop.datasets import make_object, make_room
from o3d_rpointhop.registration.model_choice import (
    ModelChoice,
    choose_model,
    cloud_cues,
    resolve_model,
)
from o3d_rpointhop.registration.result import MultiwayResult, RegistrationResult

#: A sensor outside the room's open corner, looking into it.
SENSOR = np.array([4.5, 3.5, 1.6])


def room_scan(random_state=0, sensor=SENSOR, n=3000):
    """A room corner in the frame of a sensor at ``sensor`` (axes kept)."""
    return make_room(n, random_state=random_state) - sensor


def test_a_room_seen_from_its_origin_reads_as_a_room_scan():
    cues = cloud_cues(room_scan())
    assert cues.seen_from_origin and cues.room_sized and cues.room_scan
    assert cues.front == 1.0 and cues.cone > 0.9 and 4 < cues.size < 7


@pytest.mark.parametrize(
    "cloud, seen, sized",
    [
        (make_room(3000), False, True),  # the origin on the points: no sensor there
        (make_room(3000) - make_room(3000).mean(0), False, True),  # centred: all around
        (make_object(2048), False, True),  # a unit shape about the origin
        (room_scan() * 0.05, True, False),  # a room-shaped thing 0.3 across
        (room_scan() * 20, True, False),  # 100 across: outdoor
        (room_scan() + [5e5, 6e6, 100.0], False, True),  # survey coordinates
    ],
)
def test_what_does_not_read_as_a_room_scan(cloud, seen, sized):
    cues = cloud_cues(cloud)
    assert cues.seen_from_origin is seen and cues.room_sized is sized
    assert not cues.room_scan


def test_the_cues_do_not_depend_on_the_points_order():
    cloud = room_scan()
    order = np.random.default_rng(0).permutation(len(cloud))
    a, b = cloud_cues(cloud), cloud_cues(cloud[order])
    assert a.room_scan == b.room_scan
    assert np.isclose(a.cone, b.cone) and np.isclose(a.size, b.size, rtol=1e-3)


def test_a_point_at_the_origin_is_no_sensor_view():
    cloud = np.vstack([room_scan(), [[0.0, 0.0, 0.0]]])
    assert not cloud_cues(cloud).seen_from_origin


def test_pairs_need_both_clouds_and_larger_sets_half():
    room, thing = room_scan(), make_object(2048)
    assert choose_model([room, room_scan(1)]).model == "scene"
    assert choose_model([room, thing]).model == "object"
    assert choose_model([room, room_scan(1), thing, thing]).model == "scene"
    assert choose_model([room, thing, thing]).model == "object"
    choice = choose_model([room, room_scan(1)])
    assert choice.viewpoints == "origin" and choice.room_scans == 2 and choice.n_clouds == 2
    assert "rooms scanned from their origin" in choice.reason
    assert choose_model([thing, thing]).viewpoints is None


def test_the_reason_names_what_decided():
    small = [room_scan() * 0.05, room_scan(1) * 0.05]
    assert "not room-sized" in choose_model(small).reason
    assert "not seen from their origin" in choose_model([make_object(512)] * 2).reason


def test_bad_clouds_are_named():
    bad = room_scan()
    bad[3] = np.nan
    with pytest.raises(ValueError, match="target"):
        choose_model([room_scan(), bad], ["source", "target"])
    with pytest.raises(ValueError, match="target"):
        register(room_scan(), bad)


def test_resolve_model_keeps_what_is_given():
    model = RPointHopTransformer.pretrained("object")
    assert resolve_model(model, "auto", [room_scan()] * 2) == (model, None, None)
    assert resolve_model(None, "origin", [room_scan()] * 2) == (None, "origin", None)
    named, views, choice = resolve_model("scene", "auto", [make_object(512)] * 2)
    assert named.get_params() == RPointHopTransformer.pretrained("scene").get_params()
    assert views is None and choice is None
    # The model chosen, the viewpoints given: the choice says what was used.
    chosen, views, choice = resolve_model("auto", None, [room_scan(), room_scan(1)])
    assert choice.model == "scene" and views is None and choice.viewpoints is None


def test_register_chooses_the_scene_model_for_room_scans():
    rotation = Rotation.from_euler("z", 20, degrees=True).as_matrix()
    truth = np.eye(4)
    truth[:3, :3], truth[:3, 3] = rotation, [0.2, -0.1, 0.05]
    # The source in its own sensor's frame: the target's sensor moved by the inverse.
    target = room_scan(0)
    source = (room_scan(1) - truth[:3, 3]) @ rotation
    assert cloud_cues(source).room_scan
    result = register(source, target)
    assert result.model["model"] == "scene" and result.model["viewpoints"] == "origin"
    assert "hypotheses" in result.steps[0].info  # the consensus, which the scene model states
    assert np.allclose(result.transformation[:3, 3], truth[:3, 3], atol=0.05)
    # The same clouds with the object model named: nothing chosen, RANSAC.
    named = register(source, target, "object")
    assert named.model is None and "hypotheses" not in named.steps[0].info  # RANSAC


def test_register_chooses_the_object_model_for_objects():
    cloud = make_object(1024)
    result = register(cloud + [0.1, 0.0, 0.0], cloud)
    assert result.model["model"] == "object" and result.model["viewpoints"] is None
    assert "hypotheses" not in result.steps[0].info  # RANSAC
    given = register(cloud + [0.1, 0.0, 0.0], cloud, None)  # None: the object model
    assert np.array_equal(given.transformation, result.transformation)
    assert given.model is None


def test_the_choice_is_saved_and_loaded(tmp_path):
    cloud = make_object(1024)
    result = register(cloud + [0.1, 0.0, 0.0], cloud)
    assert result.as_dict()["model"] == result.model
    result.save(tmp_path / "r.json")
    assert RegistrationResult.load(tmp_path / "r.json").model == result.model


def test_unknown_model_names_are_refused():
    cloud = make_object(256)
    with pytest.raises(ValueError, match="descriptor"):
        register(cloud, cloud, "rooms")
    with pytest.raises(ValueError, match="viewpoints"):
        register(cloud, cloud, viewpoints="sensor")


def test_multiway_records_the_choice(tmp_path):
    scans = [make_object(1024, shape_seed=3, sample_seed=s) for s in range(3)]
    result = register_multiway(scans)
    assert result.model == ModelChoice("object", None, choose_model(scans).reason, 0, 3).as_dict()
    result.save(tmp_path / "m.json")
    assert MultiwayResult.load(tmp_path / "m.json").model == result.model
    assert register_multiway(scans, "object").model is None


def test_multiway_describes_rooms_on_the_screening_axes(monkeypatch):
    """By default ``register_multiway`` describes room scans with the scene model on its
    own 96 axes; with ``SCREENING_AXES`` set, the model left to it is described on that
    many leading axes and the record says so, a model named keeps its own axes, and the
    shipped model is left as it was."""
    from o3d_rpointhop.registration import multiway

    widths = []
    prepare = multiway._prepare_scan

    def spy(index, points, voxel, worker, *rest):
        widths.append(worker.n_components)
        return prepare(index, points, voxel, worker, *rest)

    monkeypatch.setattr(multiway, "_prepare_scan", spy)
    scans = [room_scan(s, n=1500) for s in range(2)]
    assert multiway.SCREENING_AXES == {}
    plain = register_multiway(scans)
    assert plain.model["model"] == "scene" and plain.model["axes"] is None
    assert widths == [96, 96]
    widths.clear()
    monkeypatch.setattr(multiway, "SCREENING_AXES", {"scene": 32})
    chosen = register_multiway(scans)
    assert chosen.model["model"] == "scene" and chosen.model["axes"] == 32
    assert widths == [32, 32]
    assert RPointHopTransformer.pretrained("scene").n_components == 96
    widths.clear()
    named = register_multiway(scans, "scene", viewpoints="origin")
    assert named.model is None and widths == [96, 96]


def test_the_chosen_model_is_narrowed_only_where_a_width_is_set(monkeypatch):
    from o3d_rpointhop.registration import multiway
    from o3d_rpointhop.registration.multiway import chosen_model

    scene = RPointHopTransformer.pretrained("scene")
    choice = ModelChoice("scene", "origin", "rooms", 2, 2)
    assert chosen_model(scene, choice) == (scene, choice)
    monkeypatch.setattr(multiway, "SCREENING_AXES", {"scene": 32})
    narrowed, said = chosen_model(scene, choice)
    assert narrowed is not scene and scene.n_components == 96
    assert narrowed.n_components == 32 and said.axes == 32 and said.as_dict()["axes"] == 32
    assert narrowed.transform(room_scan(n=400), viewpoints="origin").shape == (400, 32)
    obj = RPointHopTransformer.pretrained("object")
    kept = ModelChoice("object", None, "objects", 0, 2)
    assert chosen_model(obj, kept) == (obj, kept)
