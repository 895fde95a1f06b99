"""A building of hundreds of fragments: tiles of real room scans, each moved, rebuilt in
one ``register_multiway`` call.

Every fragment of the chosen 3DMatch scenes (default: the four training scenes) is cut
into four tiles, 2 x 2 over its two widest principal axes, each tile reaching
:data:`OVERLAP` of the fragment's extent past the midlines so that neighbouring tiles
overlap; every tile is then moved by a seeded random rigid motion, so no tile is in its
sensor's frame. The tiles of the first fragments (all of them for the largest size) are
rebuilt with the defaults. Reported per size: the candidate pairs tried (which grow with
the tile count, not its square), edges kept, parts and tiles placed, the peak memory of
the process and its workers, the time, and how right the poses are inside each part:

- tiles of one fragment that land in one part agree on that fragment's pose (within
  :data:`TOLERANCE`), as the motions they were moved by say;
- the 3DMatch ground-truth pairs (gt.log, both fragments with a placed tile in one
  part) pass the official test (gt.info RMSE below 0.2 m) through the first tiles.

The four scenes are separate rooms: they come back as separate parts, the largest
placed, every part reconstructed (``MultiwayResult.part_poses``).

Writes ``multiway_building.json`` (and ``multiway_building_timings.json``) to
``--output``::

    python benchmarks/multiway_building.py [--sizes 64,128,all] [--model auto] [--n-jobs -1]
"""

from __future__ import annotations

import argparse
import json
import threading
import time
from pathlib import Path

import numpy as np

from o3d_rpointhop import register_multiway
from o3d_rpointhop.datasets.threedmatch import threedmatch_root
from o3d_rpointhop.evaluation._common import machine_facts
from o3d_rpointhop.evaluation.provenance import multiway_provenance
from o3d_rpointhop.evaluation.report import write_split
from o3d_rpointhop.evaluation.rooms import pairs_registered, scene_data
from o3d_rpointhop.evaluation.scene_models import TRAINING_SCENES
from o3d_rpointhop.transforms import apply_transform, random_rigid_motion, rotation_error_deg

RESULTS = Path(__file__).resolve().parents[1] / "benchmarks" / "results"
#: How far past the fragment's midlines a tile reaches, as a share of its extent.
OVERLAP = 0.2
#: Tiles of one fragment agree when their estimates of its pose differ by less.
TOLERANCE = (2.0, 0.05)  # degrees, metres


def tiles_of(points: np.ndarray) -> list[np.ndarray]:
    """A fragment's four overlapping tiles (2 x 2 over its two widest principal axes)."""
    centred = points - points.mean(axis=0)
    _, axes = np.linalg.eigh(np.cov(centred.T))
    coords = centred @ axes[:, ::-1][:, :2]  # the two widest axes
    reach = OVERLAP * (coords.max(axis=0) - coords.min(axis=0))
    tiles = []
    for sx in (-1.0, 1.0):
        for sy in (-1.0, 1.0):
            keep = (sx * coords[:, 0] > -reach[0]) & (sy * coords[:, 1] > -reach[1])
            tiles.append(points[keep])
    return tiles


def make_building(root: Path, scenes: list[str], seed: int):
    """Every fragment's tiles, moved: the tiles, for each tile its (scene, fragment id)
    and the motion it was moved by, and every scene's ground-truth pairs."""
    rng = np.random.default_rng(seed)
    tiles, owner, motions, truths = [], [], [], {}
    for scene in scenes:
        ids, points, truth = scene_data(root, scene)
        truths[scene] = truth
        for fragment, cloud in zip(ids, points, strict=True):
            for tile in tiles_of(cloud):
                motion = random_rigid_motion(rng, 2.0)
                tiles.append(apply_transform(tile, motion))
                owner.append((scene, fragment))
                motions.append(motion)
    return tiles, owner, motions, truths


class PeakMemory:
    """The largest resident memory of this process and its children together, sampled
    every ``interval`` seconds while in use (psutil, which the ``[distributed]`` extra
    installs)."""

    def __init__(self, interval: float = 0.2) -> None:
        import psutil

        self._process = psutil.Process()
        self._interval = interval
        self._stop = threading.Event()
        self.peak = 0

    def _total(self) -> int:
        total = self._process.memory_info().rss
        for child in self._process.children(recursive=True):
            try:
                total += child.memory_info().rss
            except Exception:  # a worker that ended between the listing and the read
                continue
        return total

    def _watch(self) -> None:
        while not self._stop.is_set():
            self.peak = max(self.peak, self._total())
            self._stop.wait(self._interval)

    def __enter__(self) -> PeakMemory:
        self._thread = threading.Thread(target=self._watch, daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()
        self.peak = max(self.peak, self._total())


def score(result, owner, motions, truths) -> dict:
    """Tiles placed, tiles of one fragment that agree, gt pairs registered (see the
    module), over every part of the reconstruction."""
    agree = disagree = 0
    registered = 0
    counted: set = set()
    for poses in result.part_poses:
        fragment_pose: dict = {}
        for k, pose in enumerate(poses):
            if pose is None:
                continue
            estimate = pose @ motions[k]  # the tile's fragment into the part's frame
            key = owner[k]
            if key not in fragment_pose:
                fragment_pose[key] = estimate
                continue
            first = fragment_pose[key]
            gap = np.linalg.norm(first[:3, 3] - estimate[:3, 3])
            ok = rotation_error_deg(first, estimate) < TOLERANCE[0] and gap < TOLERANCE[1]
            agree, disagree = agree + ok, disagree + (not ok)
        for scene, truth in truths.items():
            poses_of = {f: p for (s, f), p in fragment_pose.items() if s == scene}
            fresh = {
                pair: value
                for pair, value in truth.items()
                if (scene, pair) not in counted and pair[0] in poses_of and pair[1] in poses_of
            }
            counted.update((scene, pair) for pair in fresh)
            registered += pairs_registered(poses_of, fresh)
    return {
        "tiles_placed": len(result.poses) - len(result.unconnected),
        "tiles_in_parts_of_two_or_more": sum(len(p) for p in result.parts if len(p) > 1),
        "tile_pairs_of_one_fragment_agreeing": int(agree),
        "tile_pairs_of_one_fragment_disagreeing": int(disagree),
        "gt_pairs": sum(len(t) for t in truths.values()),
        "gt_pairs_registered": int(registered),
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=None)
    parser.add_argument("--scenes", default=",".join(TRAINING_SCENES))
    parser.add_argument("--sizes", default="64,128,all", help="tile counts; 'all': every tile")
    parser.add_argument("--n-jobs", type=int, default=-1)
    parser.add_argument(
        "--model", default="auto", help="register_multiway's descriptor: auto, object or scene"
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--output", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    root = threedmatch_root(args.data)
    scenes = [s for s in args.scenes.split(",") if s]
    tiles, owner, motions, truths = make_building(root, scenes, args.seed)
    out = {
        "settings": {
            "scenes": scenes,
            "tiles": len(tiles),
            "overlap": OVERLAP,
            "tolerance": TOLERANCE,
            "n_jobs": args.n_jobs,
            "model": args.model,
            "seed": args.seed,
            "machine": machine_facts()["machine"],
        },
        "runs": [],
    }
    for size in args.sizes.split(","):
        n = len(tiles) if size == "all" else min(int(size), len(tiles))
        with PeakMemory() as memory:
            start = time.perf_counter()
            result = register_multiway(
                tiles[:n], args.model, random_state=args.seed, n_jobs=args.n_jobs, progress=False
            )
            seconds = time.perf_counter() - start
        fragments = {owner[k] for k in range(n)}
        kept = {  # the pairs whose two fragments have tiles in this run
            scene: {p: v for p, v in truth.items() if {(scene, p[0]), (scene, p[1])} <= fragments}
            for scene, truth in truths.items()
        }
        run = {
            "tiles": n,
            "fragments": len(fragments),
            "model": (result.model or {}).get("model", args.model),
            "candidate_pairs": len(result.pairs),
            "pairs_per_tile": round(len(result.pairs) / n, 2),
            "edges_kept": len(result.edges),
            "parts_of_two_or_more": sum(len(p) > 1 for p in result.parts),
            **score(result, owner[:n], motions[:n], kept),
            "peak_memory_gib": round(memory.peak / 2**30, 2),
            "seconds": round(seconds, 1),
        }
        out["runs"].append(run)
        print(json.dumps(run), flush=True)
    out["provenance"] = multiway_provenance(["rpointhop"])
    write_split(out, args.output, "multiway_building")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
