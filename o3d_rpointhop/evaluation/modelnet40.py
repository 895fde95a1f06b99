"""ModelNet40 registration protocols: the paper's, resampled, noisy, partial, unseen
classes, and the angle sweep."""

from __future__ import annotations

import time
from collections.abc import Iterable

from ..descriptors import RPointHopTransformer
from ..registration.defaults import default_descriptor
from ._common import (
    Progress,
    evaluate_methods,
    fixed_resolution,
    machine_facts,
    model_facts,
)
from .methods import check_methods
from .protocols import PROTOCOLS, make_pairs
from .provenance import model_identity, run_provenance
from .records import as_rows

__all__ = ["MODELNET40_PROTOCOLS", "ANGLE_SWEEP", "run_modelnet40"]

MODELNET40_PROTOCOLS = {
    **PROTOCOLS,
    "paper-unseen-classes": "as 'paper', with a model fitted on classes 0-19 only and test "
    "shapes from classes 20-39",
    "angle-sweep": "as 'paper', with the largest Euler angle swept from 0 to 180 deg",
}
ANGLE_SWEEP = (0, 15, 30, 45, 60, 90, 120, 150, 180)
SWEEP_METHODS = ("rpointhop-svd", "rpointhop-ransac-icp", "fpfh-ransac-icp", "icp")
# Voxel of Open3D's FPFH recipe for unit-sphere objects (its tutorial's value).
MODELNET40_FPFH_VOXEL = 0.05


def run_modelnet40(
    protocols: Iterable[str],
    methods: Iterable[str],
    *,
    data=None,
    seed: int = 0,
    max_shapes: int | None = None,
    model: RPointHopTransformer | None = None,
    progress: bool = True,
) -> dict:
    """ModelNet40 registration protocols (see :data:`MODELNET40_PROTOCOLS`).

    Parameters
    ----------
    protocols, methods : iterables of str
    data : path, default=None
        Official ``modelnet40_ply_hdf5_2048`` folder or the shared-data layout.
    max_shapes : int, default=None
        Use only the first shapes of each test split (quick runs).
    model : RPointHopTransformer, default=None
        ``None`` is the pretrained model (fitted on all classes of the train subset).

    Returns
    -------
    dict
        ``{"dataset", "settings", "protocols": {name: {"summary": {method: {...}},
        "records": {...}}}}``; the angle sweep stores one summary per angle.
    """
    from ..datasets import load_modelnet40

    protocols = list(protocols)
    unknown = [p for p in protocols if p not in MODELNET40_PROTOCOLS]
    if unknown:
        raise ValueError(f"unknown protocols {unknown}; choose from {sorted(MODELNET40_PROTOCOLS)}")
    methods = check_methods(methods, "modelnet40")
    train = load_modelnet40("train", data)
    test = load_modelnet40("test", data)
    model = model if model is not None else default_descriptor()
    out = {
        "dataset": "modelnet40",
        "source": test.source,
        "settings": {
            "seed": seed,
            "test_shapes": len(test) if max_shapes is None else min(max_shapes, len(test)),
            "fpfh_voxel": MODELNET40_FPFH_VOXEL,
            "success": "rotation error < 5 deg and translation error < 0.05",
            **model_facts(model),
            **machine_facts(),
        },
        "protocols": {},
    }
    out["provenance"] = run_provenance(methods, model)
    for protocol in protocols:
        shapes, protocol_model = test.points, model
        fit_seconds = None
        if protocol == "paper-unseen-classes":
            shapes = test.points[test.labels >= 20]
            seen = train.points[train.labels < 20]
            start = time.perf_counter()
            protocol_model = RPointHopTransformer(**model.get_params()).fit(list(seen))
            fit_seconds = time.perf_counter() - start
        if max_shapes is not None:
            shapes = shapes[:max_shapes]
        if protocol == "angle-sweep":
            sweep_methods = [m for m in methods if m in SWEEP_METHODS] or methods
            bar = Progress(len(ANGLE_SWEEP) * len(sweep_methods) * len(shapes), protocol, progress)
            per_angle = {}
            for angle in ANGLE_SWEEP:
                pairs = make_pairs(shapes, "paper", seed, max_angle_deg=angle)
                per_angle[str(angle)], _ = evaluate_methods(
                    pairs, sweep_methods, model, fixed_resolution(MODELNET40_FPFH_VOXEL), seed, bar
                )
            out["protocols"][protocol] = {"angles": list(ANGLE_SWEEP), "summary": per_angle}
            continue
        base = "paper" if protocol == "paper-unseen-classes" else protocol
        pairs = make_pairs(shapes, base, seed)
        bar = Progress(len(methods) * len(pairs), protocol, progress)
        summary, records = evaluate_methods(
            pairs,
            methods,
            protocol_model,
            fixed_resolution(MODELNET40_FPFH_VOXEL),
            seed,
            bar,
            shapes,
        )
        out["protocols"][protocol] = {
            "description": MODELNET40_PROTOCOLS[protocol],
            "summary": summary,
            "records": as_rows(records),
        }
        if fit_seconds is not None:
            out["protocols"][protocol]["fit_seconds"] = fit_seconds
            out["protocols"][protocol]["fit_shapes"] = int(len(seen))
            # The given model's methods describe with a model fitted here instead.
            out["protocols"][protocol]["model"] = model_identity(protocol_model)
    return out
