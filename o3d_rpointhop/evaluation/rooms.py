"""Whole rooms from their unposed fragments: every 3DMatch scene of the data folder
rebuilt by several multiway methods in one run, scored on its ground-truth pairs.

A scene's fragments are given to each method in the order of their numbers, from their
own frames (no pose is known). A ground-truth pair (``gt.log`` of 3DMatch and 3DLoMatch,
both fragments present) counts when the relative pose of its two fragments in the
reconstruction passes the official test (``gt.info`` RMSE below 0.2 m). Reported per
scene and method: the pairs counted, the fragments placed among those that have a
ground-truth pair, and the time; the training scenes of the scene model and the
held-out scenes apart.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from ..datasets import read_gt_info, read_gt_log
from ..datasets.threedmatch import threedmatch_root
from ..descriptors import FPFHTransformer
from ..io import read_cloud
from ..registration import register_multiway
from .metrics import REGISTERED_RMSE, rmse_3dmatch
from .multiway import open3d_multiway_recipe
from .scene_models import TRAINING_SCENES

__all__ = [
    "RECALL_RMSE",
    "RECIPE_VOXEL",
    "ROOM_METHODS",
    "markdown",
    "pair_rmse",
    "pairs_registered",
    "read_truth",
    "run_rooms",
    "scene_data",
    "timings_markdown",
]

#: The official registration test: gt.info RMSE below this, in metres.
RECALL_RMSE = REGISTERED_RMSE
#: The voxel of Open3D's recipe on rooms, in metres (its tutorials' 5 cm).
RECIPE_VOXEL = 0.05
#: The methods, by name, with what they are.
ROOM_METHODS = {
    "auto": "register_multiway(scans): the defaults, the model chosen from the scans",
    "fpfh": "register_multiway(scans, FPFHTransformer(), global_method='consensus', "
    "viewpoints='origin', n_global_points=4096): FPFH through this library's multiway on "
    "the scene model's path",
    "open3d-recipe": "Open3D's multiway tutorial with FPFH + RANSAC per pair at 5 cm "
    "(evaluation.multiway.open3d_multiway_recipe)",
}


def scene_data(root: Path, scene: str):
    """The scene's fragment ids (by number), their points, and its ground-truth pairs
    ``(i, j) -> (truth, information)`` whose two fragments are present."""
    folder = Path(root) / "fragments" / scene
    ids = sorted(int(p.stem.split("_")[-1]) for p in folder.glob("cloud_bin_*.ply"))
    points = [np.asarray(read_cloud(folder / f"cloud_bin_{k}.ply").points) for k in ids]
    truth = {}
    for bench in ("3DMatch", "3DLoMatch"):
        gt = Path(root) / "benchmarks" / bench / scene
        if not (gt / "gt.log").is_file():
            continue
        info = read_gt_info(gt / "gt.info")
        for pair, matrix in read_gt_log(gt / "gt.log").items():
            if pair[0] in ids and pair[1] in ids and pair in info:
                truth[pair] = (matrix, info[pair])
    return ids, points, truth


def _relative(poses: dict[int, Any], i: int, j: int) -> np.ndarray | None:
    """Fragment ``j`` into fragment ``i``'s frame, when both are placed."""
    if poses.get(i) is None or poses.get(j) is None:
        return None
    return np.linalg.inv(poses[i]) @ poses[j]


def read_truth(gt_log: str | Path) -> dict:
    """A ``gt.log``'s pairs with the ``gt.info`` beside it: ``(i, j) -> (the 4x4 matrix
    mapping fragment j into i, its 6x6 information matrix)``.

    Raises
    ------
    FileNotFoundError
        Without the ``.info`` file the official test cannot be taken.
    ValueError
        If a pair of the log has no information matrix.
    """
    gt_log = Path(gt_log)
    info_path = gt_log.with_suffix(".info")
    if not info_path.is_file():
        raise FileNotFoundError(
            f"{info_path}: no such file; the official test needs each pair's information "
            f"matrix beside {gt_log.name}"
        )
    log, info = read_gt_log(gt_log), read_gt_info(info_path)
    missing = sorted(set(log) - set(info))
    if missing:
        raise ValueError(f"{info_path} holds no record of the pairs {missing[:5]} of {gt_log}")
    return {pair: (matrix, info[pair]) for pair, matrix in log.items()}


def pair_rmse(poses: dict[int, Any], truth: dict) -> dict[tuple[int, int], float | None]:
    """Every ground-truth pair's official error (:func:`~.metrics.rmse_3dmatch`) of the
    relative pose the poses (fragment id -> 4x4, None or absent: not placed) give its
    two fragments; None where either has no pose."""
    errors: dict[tuple[int, int], float | None] = {}
    for (i, j), (matrix, information) in truth.items():
        estimate = _relative(poses, i, j)
        errors[(i, j)] = None if estimate is None else rmse_3dmatch(estimate, matrix, information)
    return errors


def pairs_registered(poses: dict[int, Any], truth: dict) -> int:
    """How many ground-truth pairs the poses (fragment id -> 4x4 or None) register: the
    official test, :func:`pair_rmse` under :data:`RECALL_RMSE`."""
    return sum(e is not None and e < RECALL_RMSE for e in pair_rmse(poses, truth).values())


def _run_method(name: str, points: list[np.ndarray], seed: int, n_jobs: int):
    """One method's reconstruction: its poses (scan order), for ``auto`` the model it
    chose, and for this library's multiway the result (its unverified placements)."""
    if name == "open3d-recipe":
        return open3d_multiway_recipe(points, RECIPE_VOXEL, seed).poses, None, None
    if name == "fpfh":
        result = register_multiway(
            points,
            FPFHTransformer(),
            global_method="consensus",
            viewpoints="origin",
            n_global_points=4096,
            random_state=seed,
            n_jobs=n_jobs,
            progress=False,
        )
        return result.poses, None, result
    result = register_multiway(points, random_state=seed, n_jobs=n_jobs, progress=False)
    return result.poses, result.model, result


def run_rooms(
    scenes: list[str] | None = None,
    methods: tuple[str, ...] = tuple(ROOM_METHODS),
    *,
    data: Any = None,
    seed: int = 0,
    n_jobs: int = -1,
    log: Any = print,
) -> dict:
    """Rebuild every chosen 3DMatch scene with every method.

    Parameters
    ----------
    scenes : list of str, default=None
        Scene names, or parts of them; None: every scene in the data folder.
    methods : tuple of str
        Names of :data:`ROOM_METHODS`.
    data : path, default=None
        The data folder (see :func:`~o3d_rpointhop.datasets.threedmatch.threedmatch_root`).
    seed : int, default=0
    n_jobs : int, default=-1
        Cores for this library's multiway (the poses do not depend on it).
    log : callable, default=print
        Called with a line per scene and method as it finishes.

    Returns
    -------
    dict
        JSON-ready: settings, and per scene its split, fragments, ground-truth pairs
        and, per method, the pairs registered, the fragments placed, the time and, for
        this library's multiway, the placed scans beyond edges no loop checks
        (``unverified``: :meth:`~o3d_rpointhop.registration.MultiwayResult.unverified`).
    """
    unknown = [m for m in methods if m not in ROOM_METHODS]
    if unknown:
        raise ValueError(f"unknown room methods {unknown}; known: {list(ROOM_METHODS)}")
    root = threedmatch_root(data)
    found = sorted(p.name for p in (root / "fragments").iterdir() if p.is_dir())
    if scenes:
        found = [s for s in found if any(part in s for part in scenes)]
    if not found:
        raise ValueError(f"no 3DMatch scene matches {scenes} in {root / 'fragments'}")
    out: dict[str, Any] = {
        "benchmark": "rooms",
        "settings": {
            "seed": seed,
            "recall_rmse": RECALL_RMSE,
            "recipe_voxel": RECIPE_VOXEL,
            "methods": {m: ROOM_METHODS[m] for m in methods},
        },
        "scenes": {},
    }
    for scene in found:
        ids, points, truth = scene_data(root, scene)
        with_pairs = sorted({k for pair in truth for k in pair})
        entry: dict[str, Any] = {
            "split": "training" if scene in TRAINING_SCENES else "heldout",
            "fragments": len(ids),
            "gt_pairs": len(truth),
            "fragments_with_pairs": len(with_pairs),
            "methods": {},
        }
        for method in methods:
            start = time.perf_counter()
            poses, model, result = _run_method(method, points, seed, n_jobs)
            seconds = time.perf_counter() - start
            by_id = dict(zip(ids, poses, strict=True))
            row = {
                "gt_pairs_registered": pairs_registered(by_id, truth),
                "placed_with_pairs": sum(by_id[k] is not None for k in with_pairs),
                "placed": sum(p is not None for p in poses),
                "seconds": round(seconds, 1),
            }
            if result is not None:  # placed scans joined by edges no loop checks
                row["unverified"] = len(result.unverified())
            if model is not None:
                row["model"] = model["model"]
            entry["methods"][method] = row
            log(f"{scene} {method}: {row}")
        out["scenes"][scene] = entry
    return out


def _share(part: int, whole: int) -> str:
    return f"{part} / {whole} ({100.0 * part / whole:.0f} %)" if whole else "-"


def markdown(results: dict) -> str:
    """The pairs registered and fragments placed per scene and method, training and
    held-out scenes apart, with each method's totals."""
    methods = list(results["settings"]["methods"])
    lines = [
        "# Whole rooms from unposed fragments",
        "",
        f"Pairs: official gt.log pairs with both fragments present, counted when the "
        f"reconstruction's relative pose has gt.info RMSE < {results['settings']['recall_rmse']}"
        " m. Placed: fragments with a ground-truth pair that the method placed.",
        "",
    ]
    for name, text in results["settings"]["methods"].items():
        lines.append(f"- `{name}`: {text}")
    for split in ("training", "heldout"):
        scenes = {s: e for s, e in results["scenes"].items() if e["split"] == split}
        if not scenes:
            continue
        lines += [
            "",
            f"## {'Training' if split == 'training' else 'Held-out'} scenes",
            "",
            "| scene | fragments | "
            + " | ".join(f"{m}: pairs | {m}: placed" for m in methods)
            + " |",
            "|---|---|" + "---|---|" * len(methods),
        ]
        totals = {m: [0, 0, 0, 0] for m in methods}
        for scene, entry in scenes.items():
            cells = []
            for m in methods:
                row = entry["methods"][m]
                cells += [
                    _share(row["gt_pairs_registered"], entry["gt_pairs"]),
                    f"{row['placed_with_pairs']} / {entry['fragments_with_pairs']}",
                ]
                t = totals[m]
                t[0] += row["gt_pairs_registered"]
                t[1] += entry["gt_pairs"]
                t[2] += row["placed_with_pairs"]
                t[3] += entry["fragments_with_pairs"]
            model = entry["methods"].get("auto", {}).get("model")
            label = f"{scene} (auto: {model})" if model else scene
            lines.append(f"| {label} | {entry['fragments']} | " + " | ".join(cells) + " |")
        cells = []
        for m in methods:
            t = totals[m]
            cells += [_share(t[0], t[1]), f"{t[2]} / {t[3]}"]
        lines.append("| **all** | | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def timings_markdown(results: dict) -> str:
    """Each method's time per scene, and its ratio to Open3D's recipe in the same run."""
    methods = list(results["settings"]["methods"])
    lines = [
        "# Whole rooms: time per scene (seconds; ratio to Open3D's recipe, same run)",
        "",
        "| scene | " + " | ".join(methods) + " |",
        "|---|" + "---|" * len(methods),
    ]
    for scene, entry in results["scenes"].items():
        recipe = entry["methods"].get("open3d-recipe", {}).get("seconds")
        cells = []
        for m in methods:
            seconds = entry["methods"][m]["seconds"]
            ratio = f" ({seconds / recipe:.2f}x)" if recipe else ""
            cells.append(f"{seconds:.1f}{ratio}")
        lines.append(f"| {scene} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
