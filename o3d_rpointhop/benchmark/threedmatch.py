"""3DMatch / 3DLoMatch benchmark: fragment pairs with official ground truth."""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from ..rpointhop import RPointHopTransformer, default_descriptor
from ..transforms import rotation_error_deg, translation_error
from ._common import Progress, check_methods, machine_facts, model_facts
from .methods import run_method
from .metrics import match_inlier_ratio, rmse_3dmatch

__all__ = ["run_3dmatch"]


def run_3dmatch(
    methods: Iterable[str],
    *,
    data=None,
    seed: int = 0,
    model: RPointHopTransformer | None = None,
    progress: bool = True,
    max_pairs: int | None = None,
    scenes: Iterable[str] | None = None,
) -> dict:
    """3DMatch / 3DLoMatch fragment pairs with official ground truth.

    ``max_pairs``: a seeded random sample of at most this many pairs per benchmark
    (``None``: every pair). ``scenes``: only the scenes whose folder name contains one
    of these strings (``None``: all eight), chosen before the sample is drawn.

    Besides the summary per benchmark, every method's recall is reported per scene
    (``per_scene``), and the scenes the R-PointHop model was fitted on (its
    ``training_scenes_``, if any) are named in the settings, so results on scenes the
    model saw are read apart from those on scenes it did not.

    Registration recall: share of pairs whose official error (from ``gt.info``) is below
    0.2 m. Feature-match recall: share of pairs where more than 5 % of the mutual
    nearest-descriptor matches (on the registration's downsampled clouds) lie within
    0.1 m of each other under the ground truth.
    """
    from ..datasets.threedmatch import load_3dmatch_pairs
    from ..fpfh import FPFHTransformer
    from ..registration.context import RegistrationContext

    methods = check_methods(methods)
    model = model if model is not None else default_descriptor()
    pairs = load_3dmatch_pairs(data)
    if scenes is not None:
        wanted = list(scenes)
        pairs = [p for p in pairs if any(w in p.scene for w in wanted)]
        if not pairs:
            raise ValueError(f"no 3DMatch pairs in scenes matching {wanted}")
    if max_pairs is not None:
        rng = np.random.default_rng(seed)
        picked = []
        for bench in ("3DMatch", "3DLoMatch"):
            these = [p for p in pairs if p.benchmark == bench]
            keep = np.sort(rng.permutation(len(these))[:max_pairs])
            picked += [these[k] for k in keep]
        pairs = picked
    out = {
        "dataset": "3dmatch",
        "settings": {
            "seed": seed,
            "pairs_per_benchmark": "all" if max_pairs is None else f"at most {max_pairs}",
            **model_facts(model),
            **machine_facts(),
            "model_training_scenes": list(getattr(model, "training_scenes_", []) or []),
        },
        "protocols": {},
    }
    bar = Progress(len(methods) * len(pairs) + 2 * len(pairs), "3dmatch", progress)
    descriptors = {"rpointhop": model, "fpfh": FPFHTransformer(radius="auto", normal_radius="auto")}
    fmr = {name: [] for name in descriptors}
    voxels = {}  # the resolution register() picks, per pair
    for pair in pairs:
        context = RegistrationContext(pair.source, pair.target)
        voxels[id(pair)] = context.voxel_size
        for name, descriptor in descriptors.items():
            fmr[name].append({
                "pair": f"{pair.scene} {pair.i}-{pair.j}",
                "benchmark": pair.benchmark,
                "inlier_ratio": match_inlier_ratio(context, descriptor, pair.truth),
            })  # fmt: skip
            bar.step(f"fmr {name}")
    for bench in ("3DMatch", "3DLoMatch"):
        chosen = [p for p in pairs if p.benchmark == bench]
        if not chosen:
            continue
        summaries, records = {}, {}
        for method in methods:
            recs = []
            for pair in chosen:
                estimate, seconds = run_method(
                    method, pair.source, pair.target, descriptor=model,
                    voxel=voxels[id(pair)], seed=seed,
                )  # fmt: skip
                rmse = rmse_3dmatch(estimate, pair.truth, pair.information)
                recs.append({
                    "pair": f"{pair.scene} {pair.i}-{pair.j}", "overlap": pair.overlap,
                    "rmse": rmse, "registered": rmse < 0.2, "seconds": seconds,
                    "rotation_error_deg": rotation_error_deg(estimate, pair.truth),
                    "translation_error": translation_error(estimate, pair.truth),
                })  # fmt: skip
                bar.step(method)
            column = {key: [r[key] for r in recs] for key in recs[0]}
            summaries[method] = {
                "pairs": len(recs),
                "registration_recall": float(np.mean(column["registered"])),
                "median_rotation_error_deg": float(np.median(column["rotation_error_deg"])),
                "median_translation_error": float(np.median(column["translation_error"])),
                "seconds_per_pair": float(np.mean(column["seconds"])),
            }
            records[method] = recs
        feature_recall = {
            name: float(
                np.mean([r["inlier_ratio"] > 0.05 for r in rows if r["benchmark"] == bench])
            )
            for name, rows in fmr.items()
        }
        out["protocols"][bench] = {
            "summary": summaries,
            "per_scene": _per_scene(chosen, records),
            "feature_match_recall": feature_recall,
            "records": records,
            "inlier_ratios": fmr,
        }
    return out


def _per_scene(pairs, records: dict) -> dict:
    """Registration recall of every method in every scene: ``{method: {scene: {...}}}``."""
    out = {}
    for method, recs in records.items():
        out[method] = {}
        for scene in sorted({p.scene for p in pairs}):
            hits = [r["registered"] for p, r in zip(pairs, recs, strict=True) if p.scene == scene]
            out[method][scene] = {"pairs": len(hits), "registration_recall": float(np.mean(hits))}
    return out
