"""What a descriptor is, as a record names it: class, shipped model name (or
``"fitted"``), content hash, descriptor size and parameters."""

from __future__ import annotations

from typing import Any

from .._utils.provenance import json_safe
from ._fpfh import FEATURE_RADIUS_FACTOR, NORMAL_RADIUS_FACTOR, FPFHTransformer
from ._persistence import content_hash
from ._pretrained import PRETRAINED_MODELS
from ._rpointhop import RPointHopTransformer
from ._union import DescriptorUnion

__all__ = ["descriptor_identity"]


def _shipped_name(model: RPointHopTransformer, digest: str) -> str | None:
    """The shipped model ``model`` is (on its number of axes), or None."""
    for name in PRETRAINED_MODELS:
        try:
            shipped = RPointHopTransformer.pretrained(name, n_components=model.n_components)
        except ValueError:  # more axes than that file holds
            continue
        if content_hash(shipped) == digest:
            return name
    return None


def descriptor_identity(descriptor: Any) -> dict:
    """A descriptor as a record names it.

    A fitted :class:`RPointHopTransformer`: its class, the shipped model it is (on its
    number of axes) or ``"fitted"``, its :func:`content_hash`, its descriptor size, its
    parameters and, when it has them, the scenes it was fitted on. An
    :class:`FPFHTransformer`: its class, parameters and the radii's multiples of the
    resolution. A :class:`DescriptorUnion`: each part's identity by name, and the weights.
    Anything else: its class and, for an estimator, its parameters.
    """
    if isinstance(descriptor, DescriptorUnion):
        parts = descriptor.transformer_list
        return {
            "class": "o3d_rpointhop.DescriptorUnion",
            "parts": {name: descriptor_identity(part) for name, part in parts},
            "transformer_weights": json_safe(descriptor.transformer_weights),
        }
    if isinstance(descriptor, RPointHopTransformer):
        digest = content_hash(descriptor)
        out = {
            "class": "o3d_rpointhop.RPointHopTransformer",
            "model": _shipped_name(descriptor, digest) or "fitted",
            "sha256": digest,
            "n_features_out": int(descriptor.n_features_out_),
            "params": json_safe(descriptor.get_params()),
        }
        scenes = getattr(descriptor, "training_scenes_", None)
        if scenes:
            out["training_scenes"] = sorted(scenes)
        return out
    kind = type(descriptor)
    out = {"class": f"{kind.__module__.split('.')[0]}.{kind.__qualname__}"}
    if hasattr(descriptor, "get_params"):
        out["params"] = json_safe(descriptor.get_params())
    if isinstance(descriptor, FPFHTransformer):
        out["class"] = "o3d_rpointhop.FPFHTransformer"
        out["radius_factors"] = {"normals": NORMAL_RADIUS_FACTOR, "features": FEATURE_RADIUS_FACTOR}
    return out
