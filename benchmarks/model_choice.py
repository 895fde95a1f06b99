"""The automatic model choice's cues on real data: which clouds read as room scans.

``register(model="auto")`` takes the scene model, facing a sensor at the origin, for
clouds that read as rooms scanned from their origin (``registration/model_choice.py``),
and the object model for the rest. This script measures the cues and the choice on:

* ``--split training`` (what the thresholds were chosen on): the ModelNet40 training
  shapes as the pair protocols present them (source and target of every pair of the
  resampled, noisy, partial and paper protocols, seed 7), and every fragment of the
  four 3DMatch training scenes;
* ``--split heldout`` (the check): the ModelNet40 test shapes (same protocols, seed 7),
  every fragment of the four held-out 3DMatch scenes, and the Stanford bunny and
  dragon range scans (objects in metres).

For each group: the clouds, how many read as seen from their origin, as room-sized and
as room scans, how many of its pairs are given the scene model (a pair needs both
clouds), the model for all its clouds at once (as ``register_multiway`` chooses), and
the range of each cue. Writes ``model_choice_<split>.json`` and
``.md`` to ``--output`` (default ``benchmarks/results``)::

    python benchmarks/model_choice.py --split training [--data ../shared/data]
"""

from __future__ import annotations

import argparse
import json
from itertools import combinations
from pathlib import Path

import numpy as np

from o3d_rpointhop import RPointHopTransformer
from o3d_rpointhop.datasets import load_bunny, load_dragon, load_modelnet40, read_gt_log
from o3d_rpointhop.datasets.bunny import BUNNY_SCANS
from o3d_rpointhop.datasets.threedmatch import threedmatch_root
from o3d_rpointhop.evaluation._common import machine_facts
from o3d_rpointhop.evaluation.protocols import make_pairs
from o3d_rpointhop.evaluation.provenance import descriptor_provenance
from o3d_rpointhop.io import read_cloud
from o3d_rpointhop.registration.model_choice import (
    MODELS,
    ROOM_SIZE,
    SENSOR_CLEARANCE,
    SENSOR_CONE,
    SENSOR_FRONT,
    choose_model,
    cloud_cues,
)

RESULTS = Path(__file__).resolve().parents[1] / "benchmarks" / "results"
PROTOCOLS = ("resampled", "resampled-noise", "resampled-partial", "paper")
SCENES = {
    "training": (
        "7-scenes-redkitchen",
        "sun3d-hotel_umd-maryland_hotel1",
        "sun3d-hotel_umd-maryland_hotel3",
        "sun3d-mit_lab_hj-lab_hj_tea_nov_2_2012_scan1_erika",
    ),
    "heldout": (
        "sun3d-home_at-home_at_scan1_2013_jan_1",
        "sun3d-home_md-home_md_scan9_2012_sep_30",
        "sun3d-hotel_uc-scan3",
        "sun3d-mit_76_studyroom-76-1studyroom2",
    ),
}
SEED = 7


def groups(split: str, data) -> dict[str, tuple[list[np.ndarray], list[tuple[int, int]]]]:
    """The clouds of each group of ``split``, and its pairs (indices into the clouds):
    each protocol pair, each official 3DMatch / 3DLoMatch pair, each pair of scans."""
    found = {}
    shapes = load_modelnet40("train" if split == "training" else "test", data).points
    for protocol in PROTOCOLS:
        made = make_pairs(shapes, protocol, SEED)
        clouds = [c for p in made for c in (p.source, p.target)]
        found[f"ModelNet40 {protocol}"] = (clouds, [(2 * k, 2 * k + 1) for k in range(len(made))])
    root = threedmatch_root(data)
    for scene in SCENES[split]:
        folder = root / "fragments" / scene
        files = sorted(folder.glob("cloud_bin_*.ply"), key=lambda p: int(p.stem.split("_")[-1]))
        place = {int(f.stem.split("_")[-1]): k for k, f in enumerate(files)}
        pairs = set()
        for bench in ("3DMatch", "3DLoMatch"):
            for i, j in read_gt_log(root / "benchmarks" / bench / scene / "gt.log"):
                if i in place and j in place:  # both fragments in the data
                    pairs.add((place[i], place[j]))
        clouds = [np.asarray(read_cloud(f).points) for f in files]
        found[f"3DMatch {scene}"] = (clouds, sorted(pairs))
    if split == "heldout":
        scan_sets = {"bunny": load_bunny(BUNNY_SCANS, data), "dragon": load_dragon(data)}
        for name, scans in scan_sets.items():
            clouds = [s.points for s in scans.values()]
            found[f"Stanford {name} scans"] = (clouds, list(combinations(range(len(clouds)), 2)))
    return found


def summary(clouds: list[np.ndarray], pairs: list[tuple[int, int]]) -> dict:
    cues = [cloud_cues(c) for c in clouds]
    scene_pairs = sum(choose_model([clouds[i], clouds[j]]).model == "scene" for i, j in pairs)

    def span(name):
        values = [getattr(c, name) for c in cues]
        return [round(float(min(values)), 3), round(float(max(values)), 3)]

    return {
        "clouds": len(cues),
        "seen_from_origin": sum(c.seen_from_origin for c in cues),
        "room_sized": sum(c.room_sized for c in cues),
        "room_scans": sum(c.room_scan for c in cues),
        "pairs": len(pairs),
        "scene_pairs": scene_pairs,
        "all_clouds_model": choose_model(clouds).model,
        **{name: span(name) for name in ("size", "cone", "front", "clearance")},
    }


def markdown(split: str, rows: dict[str, dict]) -> str:
    lines = [
        f"# The automatic model choice's cues, {split} data",
        "",
        f"Thresholds: seen from the origin when cone >= {SENSOR_CONE}, front >= "
        f"{SENSOR_FRONT} and clearance within {SENSOR_CLEARANCE[0]:g}-{SENSOR_CLEARANCE[1]:g}; "
        "room-sized when the size is "
        f"within {ROOM_SIZE[0]:g}-{ROOM_SIZE[1]:g}. Ranges are min-max over the group.",
        "",
        "| group | clouds | seen from origin | room-sized | room scans | pairs given the "
        "scene model | all clouds at once | size | cone | front | clearance |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, row in rows.items():
        ranges = " | ".join(
            f"{row[k][0]:g}-{row[k][1]:g}" for k in ("size", "cone", "front", "clearance")
        )
        lines.append(
            f"| {name} | {row['clouds']} | {row['seen_from_origin']} | {row['room_sized']} "
            f"| **{row['room_scans']}** | {row['scene_pairs']} / {row['pairs']} "
            f"| {row['all_clouds_model']} | {ranges} |"
        )
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--split", choices=tuple(SCENES), default="training")
    parser.add_argument("--data", default=None)
    parser.add_argument("--output", default=str(RESULTS))
    args = parser.parse_args(argv)
    found = groups(args.split, args.data)
    rows = {name: summary(clouds, pairs) for name, (clouds, pairs) in found.items()}
    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    record = {
        "split": args.split,
        "seed": SEED,
        "thresholds": {
            "room_size": list(ROOM_SIZE),
            "sensor_cone": SENSOR_CONE,
            "sensor_front": SENSOR_FRONT,
            "sensor_clearance": list(SENSOR_CLEARANCE),
        },
        "groups": rows,
        "machine": machine_facts(),
        "provenance": descriptor_provenance(
            {f"rpointhop-{name}": RPointHopTransformer.pretrained(name) for name in MODELS}
        ),
    }
    (out / f"model_choice_{args.split}.json").write_text(json.dumps(record, indent=2) + "\n")
    text = markdown(args.split, rows)
    (out / f"model_choice_{args.split}.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
