"""Choose ``register_multiway``'s free-space limit (``max_violation``) on training scenes.

Every fragment of each chosen 3DMatch scene is rebuilt by ``register_multiway`` with
its defaults (the model chosen from the scans: the scene model facing the sensors) and
each candidate ``max_violation`` (``none``: no check), and scored on the scene's
ground-truth pairs as the rooms benchmark scores them (``evaluation/rooms.py``: gt.log
pairs of 3DMatch and 3DLoMatch, official RMSE test). Writes
``free_space_selection.json`` and ``.md`` to ``--output``::

    python benchmarks/free_space_selection.py --scenes redkitchen,hotel1,hotel3,lab_hj
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from o3d_rpointhop import RPointHopTransformer, register_multiway
from o3d_rpointhop.datasets.threedmatch import threedmatch_root
from o3d_rpointhop.evaluation.provenance import descriptor_provenance
from o3d_rpointhop.evaluation.report import write_split
from o3d_rpointhop.evaluation.rooms import pairs_registered, scene_data
from o3d_rpointhop.evaluation.scene_models import TRAINING_SCENES

RESULTS = Path(__file__).resolve().parents[1] / "benchmarks" / "results"
CANDIDATES = ("none", "0.05", "0.08", "0.1", "0.12", "0.15")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", default=",".join(TRAINING_SCENES))
    parser.add_argument("--candidates", default=",".join(CANDIDATES))
    parser.add_argument("--data", default=None)
    parser.add_argument("--n-jobs", type=int, default=-1)
    parser.add_argument("--output", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    root = threedmatch_root(args.data)
    wanted = [s for s in args.scenes.split(",") if s]
    scenes = [
        p.name for p in sorted((root / "fragments").iterdir()) if any(w in p.name for w in wanted)
    ]
    held = [s for s in scenes if s not in TRAINING_SCENES]
    if held:
        parser.error(f"choose on training scenes only, not {held}")
    candidates = [c.strip() for c in args.candidates.split(",")]
    out = {"candidates": candidates, "scenes": {}}
    totals = {c: [0, 0] for c in candidates}
    for scene in scenes:
        ids, points, truth = scene_data(root, scene)
        entry = {"gt_pairs": len(truth), "fragments": len(ids), "runs": {}}
        for candidate in candidates:
            limit = None if candidate == "none" else float(candidate)
            start = time.perf_counter()
            result = register_multiway(
                points, max_violation=limit, n_jobs=args.n_jobs, progress=False
            )
            poses = dict(zip(ids, result.poses, strict=True))
            row = {
                "gt_pairs_registered": pairs_registered(poses, truth),
                "placed": sum(p is not None for p in result.poses),
                "edges": len(result.edges),
                "model": result.model["model"],
                "seconds": round(time.perf_counter() - start, 1),
            }
            entry["runs"][candidate] = row
            totals[candidate][0] += row["gt_pairs_registered"]
            totals[candidate][1] += len(truth)
            print(scene, candidate, json.dumps(row), flush=True)
        out["scenes"][scene] = entry
    out["totals"] = {c: {"registered": t[0], "gt_pairs": t[1]} for c, t in totals.items()}
    out["provenance"] = descriptor_provenance(
        {f"rpointhop-{m}": RPointHopTransformer.pretrained(m) for m in ("object", "scene")}
    )
    lines = [
        "# register_multiway's free-space limit, training scenes",
        "",
        "Ground-truth pairs registered (gt.log of 3DMatch and 3DLoMatch, RMSE < 0.2 m) and "
        "fragments placed, per candidate max_violation.",
        "",
        "| scene | " + " | ".join(candidates) + " |",
        "|---|" + "---|" * len(candidates),
    ]
    for scene, entry in out["scenes"].items():
        cells = [
            f"{entry['runs'][c]['gt_pairs_registered']} / {entry['gt_pairs']} "
            f"({entry['runs'][c]['placed']} of {entry['fragments']} placed)"
            for c in candidates
        ]
        lines.append(f"| {scene} | " + " | ".join(cells) + " |")
    lines.append(
        "| **all** | " + " | ".join(f"{totals[c][0]} / {totals[c][1]}" for c in candidates) + " |"
    )
    text = "\n".join(lines) + "\n"
    write_split(out, args.output, "free_space_selection", lambda kept: text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
