"""3DMatch / 3DLoMatch benchmark: fragment pairs with official ground truth."""

from __future__ import annotations

import time
from collections.abc import Iterable

import numpy as np

from ..descriptors import FPFHTransformer, RPointHopTransformer
from ..registration.context import RegistrationContext
from ..registration.defaults import DEFAULT_GLOBAL_POINTS, default_descriptor, resolve_global_points
from ..transforms import rotation_error_deg, translation_error
from ._common import Progress, machine_facts, model_facts
from .methods import METHODS, check_methods, run_method, shipped_scene_model
from .metrics import match_inliers, mcnemar, rmse_3dmatch
from .scene_models import leave_one_scene_out

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
    rotate: bool = False,
) -> dict:
    """3DMatch / 3DLoMatch fragment pairs with official ground truth.

    ``max_pairs``: a seeded random sample of at most this many pairs per benchmark
    (``None``: every pair). ``scenes``: only the scenes whose folder name contains one
    of these strings (``None``: all eight), chosen before the sample is drawn.

    ``model`` is the descriptor of the ``rpointhop-*`` methods (default: the
    pretrained ModelNet40 model on 128 axes); ``rpointhop-scene`` uses the shipped
    scene model and ``rpointhop-loso``, for each pair, a scene model fitted on the
    fragments of every other scene in the data folder (fitted at the start of the run).

    Besides the summary per benchmark, every method's recall is reported per scene
    (``per_scene``). The scenes the models were fitted on (``training_scenes_`` of
    ``model`` and of the scene model, if used) are named in the settings, and the
    summary is repeated over the other scenes alone (``summary_unseen_scenes``), so
    results on scenes a model saw are read apart from those on scenes it did not.
    Rotation and translation errors are medians over the registered pairs.

    ``rotate``: every source fragment is first turned about its centroid by a rotation
    drawn uniformly over SO(3) (seeded), so that no method can lean on the fragments'
    shared upright frame; errors are measured in the original frames.

    Registration recall: share of pairs whose official error (from ``gt.info``) is below
    0.2 m. Feature-match recall: share of pairs where more than 5 % of the mutual
    nearest-descriptor matches (on the registration's downsampled clouds) lie within
    0.1 m of each other under the ground truth; the median share (inlier ratio) and
    number (inlier count) of those matches are reported beside it. Every two methods
    are compared on the same pairs by McNemar's exact test (``paired``).
    """
    from ..datasets.threedmatch import load_3dmatch_pairs

    methods = check_methods(methods, "3dmatch")
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
    motions = {}  # a turned source's motion, by pair
    if rotate:
        turned = [_turned(p, seed, k) for k, p in enumerate(pairs)]
        pairs = [p for p, _ in turned]
        motions = {id(p): motion for p, motion in turned}
    pair_scenes = sorted({p.scene for p in pairs})
    uses = {METHODS[m].model for m in methods}
    scene_model = shipped_scene_model() if "scene" in uses else None
    seen = set(getattr(model, "training_scenes_", None) or [])
    if scene_model is not None:
        seen |= set(scene_model.training_scenes_)
    out = {
        "dataset": "3dmatch",
        "settings": {
            "seed": seed,
            "pairs_per_benchmark": "all" if max_pairs is None else f"at most {max_pairs}",
            "source_turned": rotate,
            **model_facts(model),
            **machine_facts(),
            "model_training_scenes": sorted(seen),
        },
        "protocols": {},
    }
    loso = {}
    if "loso" in uses:
        start = time.perf_counter()
        fitting = Progress(len(pair_scenes), "leave-one-scene-out models", progress)
        loso = leave_one_scene_out(pair_scenes, data, progress=fitting.step)
        out["settings"]["leave_one_scene_out"] = {
            "models": len(loso),
            "fragments_per_model": {s: int(m.n_training_clouds_) for s, m in loso.items()},
            "fit_seconds": time.perf_counter() - start,
        }

    def descriptor_of(method: str, pair):
        kind = METHODS[method].model
        if kind == "loso":
            return loso[pair.scene]
        return scene_model if kind == "scene" else model

    # Feature-match recall of each descriptor the methods use, on the clouds register()
    # describes with it (its resolution and, for scene models, 4096 points): by name,
    # a method that uses it (None: FPFH).
    fpfh = FPFHTransformer(radius="auto", normal_radius="auto")
    families = {"fpfh": None}
    for family, kind in (
        ("rpointhop", "given"),
        ("scene", "scene"),
        ("leave-one-scene-out", "loso"),
    ):
        first = next((m for m in methods if METHODS[m].model == kind), None)
        if first is not None:
            families[family] = first
    bar = Progress((len(methods) + len(families)) * len(pairs), "3dmatch", progress)
    fmr = {name: [] for name in families}
    voxels = {}  # the resolution register() picks, per pair
    for pair in pairs:
        # One context per global cloud size (FPFH and an unstated model share 2048).
        contexts = {DEFAULT_GLOBAL_POINTS: RegistrationContext(pair.source, pair.target)}
        voxels[id(pair)] = contexts[DEFAULT_GLOBAL_POINTS].voxel_size
        for name, method in families.items():
            descriptor = fpfh if method is None else descriptor_of(method, pair)
            size = resolve_global_points("auto", descriptor)
            if size not in contexts:
                contexts[size] = RegistrationContext(pair.source, pair.target, n_global_points=size)
            own = contexts[size]
            ratio, count = match_inliers(own, descriptor, pair.truth)
            fmr[name].append(
                {
                    "pair": f"{pair.scene} {pair.i}-{pair.j}",
                    "benchmark": pair.benchmark,
                    "inlier_ratio": ratio,
                    "inlier_count": count,
                }
            )
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
                    method,
                    pair.source,
                    pair.target,
                    descriptor=descriptor_of(method, pair),
                    voxel=voxels[id(pair)],
                    seed=seed,
                )
                # Errors in the pair's original frames (a turned source turned back).
                motion = motions.get(id(pair), np.eye(4))
                estimate, truth = estimate @ motion, pair.truth @ motion
                rmse = rmse_3dmatch(estimate, truth, pair.information)
                recs.append(
                    {
                        "pair": f"{pair.scene} {pair.i}-{pair.j}",
                        "overlap": pair.overlap,
                        "rmse": rmse,
                        "registered": rmse < 0.2,
                        "seconds": seconds,
                        "rotation_error_deg": rotation_error_deg(estimate, truth),
                        "translation_error": translation_error(estimate, truth),
                    }
                )
                bar.step(method)
            summaries[method] = _summary(recs)
            records[method] = recs
        feature_recall, inliers = {}, {}
        for name, rows in fmr.items():
            mine = [r for r in rows if r["benchmark"] == bench]
            feature_recall[name] = float(np.mean([r["inlier_ratio"] > 0.05 for r in mine]))
            inliers[name] = {
                "median_inlier_ratio": float(np.median([r["inlier_ratio"] for r in mine])),
                "median_inlier_count": float(np.median([r["inlier_count"] for r in mine])),
            }
        paired = {
            f"{a} vs {b}": mcnemar(
                [r["registered"] for r in records[a]], [r["registered"] for r in records[b]]
            )
            for k, a in enumerate(methods)
            for b in methods[k + 1 :]
        }
        unseen = [k for k, p in enumerate(chosen) if p.scene not in seen]
        out["protocols"][bench] = {
            "summary": summaries,
            "per_scene": _per_scene(chosen, records),
            "feature_match_recall": feature_recall,
            "match_inliers": inliers,
            "paired": paired,
            "records": records,
            "inlier_ratios": fmr,
        }
        if unseen and len(unseen) < len(chosen):  # some pairs are in scenes a model saw
            out["protocols"][bench]["summary_unseen_scenes"] = {
                method: _summary([recs[k] for k in unseen]) for method, recs in records.items()
            }
    return out


def _summary(recs: list[dict]) -> dict:
    column = {key: [r[key] for r in recs] for key in recs[0]}
    registered = [r for r in recs if r["registered"]]
    return {
        "pairs": len(recs),
        "registration_recall": float(np.mean(column["registered"])),
        # Errors of the registered pairs (the official protocol's): a failed pair's
        # error says only that it failed.
        "median_rotation_error_deg": float(np.median([r["rotation_error_deg"] for r in registered]))
        if registered
        else None,
        "median_translation_error": float(np.median([r["translation_error"] for r in registered]))
        if registered
        else None,
        "seconds_per_pair": float(np.mean(column["seconds"])),
    }


def _per_scene(pairs, records: dict) -> dict:
    """Registration recall of every method in every scene: ``{method: {scene: {...}}}``."""
    out = {}
    for method, recs in records.items():
        out[method] = {}
        for scene in sorted({p.scene for p in pairs}):
            hits = [r["registered"] for p, r in zip(pairs, recs, strict=True) if p.scene == scene]
            out[method][scene] = {"pairs": len(hits), "registration_recall": float(np.mean(hits))}
    return out


def _turned(pair, seed: int, k: int):
    """``pair`` with its source turned about its centroid by a seeded rotation, uniform
    over SO(3), and the motion that maps the original source onto the turned one."""
    import dataclasses

    from scipy.spatial.transform import Rotation

    rotation = Rotation.random(random_state=np.random.default_rng([seed, k])).as_matrix()
    centre = pair.source.mean(axis=0)
    motion = np.eye(4)
    motion[:3, :3], motion[:3, 3] = rotation, centre - rotation @ centre
    turned = dataclasses.replace(
        pair,
        source=(pair.source - centre) @ rotation.T + centre,
        truth=pair.truth @ np.linalg.inv(motion),
    )
    return turned, motion
