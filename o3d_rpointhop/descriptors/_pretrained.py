"""The models shipped in ``o3d_rpointhop/data``: their names, files and default axes."""

from __future__ import annotations

from contextlib import AbstractContextManager
from importlib.resources import as_file, files
from pathlib import Path

__all__ = ["PRETRAINED_MODELS", "PRETRAINED_COMPONENTS", "pretrained_path"]

#: The shipped models by name, and their files in ``o3d_rpointhop/data``.
PRETRAINED_MODELS = {
    "modelnet40": "rpointhop_modelnet40.npz",
    "object": "rpointhop_object.npz",
    "scene": "rpointhop_scene.npz",
    "scene-fpfh": "rpointhop_scene_fpfh.npz",
}
#: What :meth:`RPointHopTransformer.pretrained` returns by default, by name: the
#: ModelNet40 model's full descriptor (the paper's), the one-hop object model's full
#: 24-D descriptor, and the scene models on the 96 principal axes they were chosen and
#: measured with (docs/model_card.md).
PRETRAINED_COMPONENTS = {"modelnet40": None, "object": None, "scene": 96, "scene-fpfh": 96}


def pretrained_path(name: str) -> AbstractContextManager[Path]:
    """A context giving the file of the shipped model ``name`` as a path on disk (a
    temporary copy when the package is not installed as plain files)."""
    return as_file(files("o3d_rpointhop") / "data" / PRETRAINED_MODELS[name])
