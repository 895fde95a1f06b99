"""Choose a setting of ``register_multiway`` on the training scenes' whole rooms.

Every fragment of each chosen 3DMatch scene is rebuilt by ``register_multiway`` with
its defaults (the model chosen from the scans: the scene model facing the sensors) but
the setting, at each candidate value, and scored on the scene's ground-truth pairs as
the rooms benchmark scores them (``evaluation/rooms.py``: gt.log pairs of 3DMatch and
3DLoMatch, official RMSE test), with the time of each rebuild. Settings:

- ``max_violation``: the free-space limit of an edge (``none``: no check);
- ``screening_queries``: the share of the consensus's cap of matches each direction of
  a screening searches from (``multiway.SCREENING_QUERIES``; ``none``: every point);
- ``screening``: ``axes/hypotheses``, the scene model's leading axes the scans are
  described on (``multiway.SCREENING_AXES``) and the hypotheses each screening
  verifies (``multiway.SCREENING_HYPOTHESES``).

Writes ``<stem>.json`` / ``.md`` and their timings to ``--output``::

    python benchmarks/rooms_selection.py --setting screening_queries \\
        --candidates none,0.375,0.5,0.75 --stem screening_queries_selection
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
from o3d_rpointhop.registration import multiway

RESULTS = Path(__file__).resolve().parents[1] / "benchmarks" / "results"
SETTINGS = {
    "max_violation": ("none", "0.05", "0.08", "0.1", "0.12", "0.15"),
    "screening_queries": ("none", "0.375", "0.5", "0.75"),
    "screening": ("96/16", "96/8", "32/16", "32/12", "32/8"),
}


def _number(candidate: str) -> float | None:
    """A numeric candidate; ``none``: None."""
    return None if candidate == "none" else float(candidate)


def _values(setting: str, candidate: str) -> dict:
    """The module settings of ``multiway`` a candidate of ``screening`` or
    ``screening_queries`` stands for."""
    if setting == "screening":
        axes, hypotheses = (int(v) for v in candidate.split("/"))
        return {"SCREENING_AXES": {"scene": axes}, "SCREENING_HYPOTHESES": hypotheses}
    return {"SCREENING_QUERIES": _number(candidate)}


def _rebuild(setting: str, candidate: str, points, n_jobs: int):
    """``register_multiway(points)`` with ``setting`` at ``candidate``."""
    if setting == "max_violation":
        limit = _number(candidate)
        return register_multiway(points, max_violation=limit, n_jobs=n_jobs, progress=False)
    values = _values(setting, candidate)
    defaults = {name: getattr(multiway, name) for name in values}
    # Applied to the model and the step before the pairs are sent to the workers.
    for name, value in values.items():
        setattr(multiway, name, value)
    try:
        return register_multiway(points, n_jobs=n_jobs, progress=False)
    finally:
        for name, value in defaults.items():
            setattr(multiway, name, value)


def _table(out: dict, heading: list[str], cell) -> str:
    """A table of every scene by candidate under ``heading``; ``cell(entry, run)`` is a
    scene's cell for one candidate's run."""
    candidates = out["candidates"]
    lines = [
        *heading,
        "| scene | " + " | ".join(candidates) + " |",
        "|---|" + "---|" * len(candidates),
    ]
    for scene, entry in out["scenes"].items():
        cells = [cell(entry, entry["runs"][c]) for c in candidates]
        lines.append(f"| {scene} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _markdown(out: dict, setting: str) -> str:
    totals = out["totals"]
    text = _table(
        out,
        [
            f"# register_multiway's {setting}, training scenes",
            "",
            "Ground-truth pairs registered (gt.log of 3DMatch and 3DLoMatch, RMSE < 0.2 m) "
            f"and fragments placed, per candidate {setting}.",
            "",
        ],
        lambda entry, run: (
            f"{run['gt_pairs_registered']} / {entry['gt_pairs']} "
            f"({run['placed']} of {entry['fragments']} placed)"
        ),
    )
    return (
        text
        + "| **all** | "
        + " | ".join(
            f"{totals[c]['registered']} / {totals[c]['gt_pairs']}" for c in out["candidates"]
        )
        + " |\n"
    )


def _timings_markdown(out: dict, setting: str) -> str:
    heading = [f"# register_multiway's {setting}, training scenes: seconds per rebuild", ""]
    return _table(out, heading, lambda entry, run: f"{run['seconds']}")


def main(argv=None, setting: str | None = None, stem: str | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    if setting is None:
        parser.add_argument("--setting", choices=sorted(SETTINGS), required=True)
        parser.add_argument("--stem", default=None)
    parser.add_argument("--scenes", default=",".join(TRAINING_SCENES))
    parser.add_argument("--candidates", default=None)
    parser.add_argument("--data", default=None)
    parser.add_argument("--n-jobs", type=int, default=-1)
    parser.add_argument("--output", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    setting = setting or args.setting
    stem = stem or getattr(args, "stem", None) or f"{setting}_selection"
    root = threedmatch_root(args.data)
    wanted = [s for s in args.scenes.split(",") if s]
    scenes = [
        p.name for p in sorted((root / "fragments").iterdir()) if any(w in p.name for w in wanted)
    ]
    held = [s for s in scenes if s not in TRAINING_SCENES]
    if held:
        parser.error(f"choose on training scenes only, not {held}")
    candidates = [c.strip() for c in (args.candidates or ",".join(SETTINGS[setting])).split(",")]
    out = {"setting": setting, "candidates": candidates, "scenes": {}}
    totals = {c: [0, 0] for c in candidates}
    for scene in scenes:
        ids, points, truth = scene_data(root, scene)
        entry = {"gt_pairs": len(truth), "fragments": len(ids), "runs": {}}
        for candidate in candidates:
            start = time.perf_counter()
            result = _rebuild(setting, candidate, points, args.n_jobs)
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
    text = _markdown(out, setting)
    write_split(
        out, args.output, stem, lambda kept: text, lambda timed: _timings_markdown(timed, setting)
    )
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
