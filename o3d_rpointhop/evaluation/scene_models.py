"""Scene models: the recipe of the shipped scene model, and leave-one-scene-out models.

One recipe serves both: ``scripts/fit_scene_model.py`` fits the shipped model on the four
:data:`TRAINING_SCENES`; ``o3d-rpointhop benchmark 3dmatch`` fits, for every scene, a
model on the fragments of all the *other* scenes (:func:`leave_one_scene_out`), so that
every scene gets a model that never saw it.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np

from ..datasets.threedmatch import threedmatch_root
from ..descriptors import RPointHopTransformer
from ..io import read_cloud
from ..registration.context import global_points

__all__ = [
    "FIT_POINTS",
    "FIT_VIEWPOINTS",
    "REGISTRATION_POINTS",
    "SCENE_FPFH_PARAMS",
    "SCENE_PARAMS",
    "TRAINING_SCENES",
    "fit_scene_model",
    "leave_one_scene_out",
    "scene_fragments",
    "scene_names",
]

#: The scenes the shipped scene model is fitted on (and every scene setting tuned on).
TRAINING_SCENES = (
    "7-scenes-redkitchen",
    "sun3d-hotel_umd-maryland_hotel1",
    "sun3d-hotel_umd-maryland_hotel3",
    "sun3d-mit_lab_hj-lab_hj_tea_nov_2_2012_scan1_erika",
)
#: The scene model's settings: the paper's scene attributes, one hop of 96 neighbours
#: on 96 principal axes; chosen on pairs of the training scenes against 2 to 4 hops,
#: azimuth pooling and other neighbourhood sizes (docs/benchmarks.md, "Scenes").
SCENE_PARAMS = dict(
    attributes=("xyz", "normal", "eigen"),
    lrf_neighbors=64,
    n_neighbors=(96,),
    hop_sizes=(1.0,),
    n_components=96,
    random_state=0,
)
#: The scene model with FPFH histograms among its hop-1 attributes (what PCRP, the
#: authors' retrieval work after R-PointHop, puts in its first hop): the shipped
#: ``pretrained("scene-fpfh")``, an option (docs/low_overlap.md, "FPFH histograms in
#: the first hop").
SCENE_FPFH_PARAMS = dict(SCENE_PARAMS, attributes=("xyz", "normal", "eigen", "fpfh"))
#: Every training fragment is downsampled as ``register()`` would for this many points
#: (the density the model is used at).
FIT_POINTS = 4096
#: The fragments are fitted with their frames facing the sensor: every 3DMatch fragment
#: is in its camera's frame, so the viewpoint is the origin.
FIT_VIEWPOINTS = "origin"
#: What a scene model tells ``register()`` (``registration_points_``): 4096 points per
#: fragment, chosen on the training scenes (docs/benchmarks.md, "Scenes").
REGISTRATION_POINTS = 4096
#: The global step a scene model tells ``register(global_method="auto")``
#: (``registration_global_method_``): the consensus, chosen on every pair of the
#: training scenes (recall 3DMatch / 3DLoMatch with the shipped model: RANSAC 77.6 /
#: 21.2 %, consensus 75.8 / 29.8 %; docs/consensus.md).
REGISTRATION_GLOBAL_METHOD = "consensus"


def scene_names(data: str | Path | None = None) -> list[str]:
    """The scene folders under the 3DMatch ``fragments/`` folder, sorted."""
    folder = threedmatch_root(data) / "fragments"
    names = sorted(p.name for p in folder.iterdir() if p.is_dir())
    if not names:
        raise FileNotFoundError(f"no 3DMatch scene folders in {folder}")
    return names


def scene_fragments(
    scene: str, data: str | Path | None = None, n_points: int = FIT_POINTS
) -> list[np.ndarray]:
    """Every fragment of ``scene`` as ``register()``'s global step sees it at
    ``n_points`` points (:func:`~o3d_rpointhop.registration.context.global_points`)."""
    folder = threedmatch_root(data) / "fragments" / scene
    paths = sorted(folder.glob("cloud_bin_*.ply"), key=lambda p: int(p.stem.split("_")[-1]))
    if not paths:
        raise FileNotFoundError(f"no fragments in {folder}")
    return [global_points(read_cloud(p), n_points) for p in paths]


def fit_scene_model(
    scenes: Iterable[str],
    data: str | Path | None = None,
    *,
    fragments: dict[str, list[np.ndarray]] | None = None,
    n_points: int = FIT_POINTS,
    **params,
) -> RPointHopTransformer:
    """A scene model fitted on every fragment of ``scenes``.

    Parameters
    ----------
    scenes : iterable of str
        Scene folder names.
    data : path, default=None
        The data folder (``data_home()`` when None).
    fragments : dict, default=None
        Already-read fragments by scene (:func:`scene_fragments`), to read each only once.
    n_points : int, default=FIT_POINTS
        Size each fragment is downsampled to for fitting (when not given ``fragments``).
    **params
        Overrides of :data:`SCENE_PARAMS`.

    Returns
    -------
    RPointHopTransformer
        With ``training_scenes_`` (the scene names), ``registration_points_``
        (:data:`REGISTRATION_POINTS`) and ``registration_global_method_``
        (:data:`REGISTRATION_GLOBAL_METHOD`).
    """
    scenes = list(scenes)
    fragments = fragments or {}
    clouds = []
    for scene in scenes:
        clouds += fragments.get(scene) or scene_fragments(scene, data, n_points)
    model = RPointHopTransformer(**{**SCENE_PARAMS, **params}).fit(
        clouds, viewpoints=FIT_VIEWPOINTS
    )
    model.training_scenes_ = scenes
    model.registration_points_ = REGISTRATION_POINTS
    model.registration_global_method_ = REGISTRATION_GLOBAL_METHOD
    return model


def leave_one_scene_out(
    scenes: Iterable[str], data: str | Path | None = None, progress=None, **params
) -> dict[str, RPointHopTransformer]:
    """For every scene in ``scenes``: a scene model fitted on all the other scenes in the
    data folder (seven of the eight 3DMatch test scenes), never on that scene.

    ``progress``: called with each scene's name after its model is fitted. ``params``:
    overrides of :data:`SCENE_PARAMS`. Every fragment is read once.
    """
    everything = scene_names(data)
    fragments = {scene: scene_fragments(scene, data) for scene in everything}
    models = {}
    for scene in scenes:
        others = [s for s in everything if s != scene]
        models[scene] = fit_scene_model(others, data, fragments=fragments, **params)
        if progress is not None:
            progress(scene)
    return models
