"""When to ask FPFH: the fallback's ``min_support``, chosen on pairs the model never saw,
without touching a held-out scene.

``register()``'s scene path runs the scene model's consensus alone and asks FPFH's
consensus too only when the model's estimate explains under ``min_support`` of its
matches (``PooledMatcher(combine="fallback")``). On the scenes the shipped model was
fitted on, the model is strong and rarely asks, so those pairs cannot tell thresholds
apart (docs/low_overlap.md). Here every training scene is registered with a scene model
fitted on the *other three* training scenes (the shipped model's recipe,
``evaluation.scene_models.fit_scene_model``), as a held-out scene meets the shipped
model: every official pair (non-consecutive fragments, 3DMatch and 3DLoMatch), the
sensor at the origin, run twice through ``register()``: FPFH never asked
(``min_support=0``: the model alone, whose support is recorded) and always asked
(``min_support=1``: both consensuses, every hypothesis verified together). The fallback
at a threshold ``t`` gives the second where the first's support is under ``t``, else the
first, so every threshold of :data:`THRESHOLDS` is read off the two runs.

Measured with it: the models of the other scenes register every pair exactly as the
shipped model does. The scene model's one hop keeps every direction its attributes
vary in, so any two fits describe a cloud up to a rotation of the descriptor space
(distances between descriptors agree to 5e-7 relative): the matches, and with them the
results, do not depend on the scenes it was fitted on. The table is therefore the
shipped model's on its training pairs, too.

The rule: the most pairs registered (3DMatch and 3DLoMatch together); among equals, the
smallest threshold (FPFH asked the least, the least time).

Writes ``benchmarks/results/fallback_selection.{json,md}``.

Usage: python benchmarks/fallback_selection.py [--data PATH] [--jobs N]
"""

from __future__ import annotations

import argparse
import json
import warnings
from pathlib import Path

from joblib import Parallel, delayed

RESULTS = Path(__file__).resolve().parent / "results"
THRESHOLDS = (0.0, 0.005, 0.01, 0.015, 0.02, 0.03, 0.05, 0.1, 1.0)


def _models(data) -> dict:
    """Per training scene, a scene model fitted on the other three."""
    from o3d_rpointhop.evaluation.scene_models import (
        TRAINING_SCENES,
        fit_scene_model,
        scene_fragments,
    )

    fragments = {scene: scene_fragments(scene, data) for scene in TRAINING_SCENES}
    return {
        scene: fit_scene_model(
            [s for s in TRAINING_SCENES if s != scene], data, fragments=fragments
        )
        for scene in TRAINING_SCENES
    }


def _pairs(data) -> list:
    from o3d_rpointhop.datasets import load_3dmatch_pairs
    from o3d_rpointhop.evaluation.scene_models import TRAINING_SCENES
    from o3d_rpointhop.evaluation.threedmatch import official_pairs

    return [p for p in official_pairs(load_3dmatch_pairs(data)) if p.scene in TRAINING_SCENES]


def _step(min_support: float):
    from o3d_rpointhop import ConsensusGlobal, PooledMatcher

    matcher = PooledMatcher.with_fpfh(combine="fallback").set_params(min_support=min_support)
    return ConsensusGlobal(matcher=matcher)


def _run(pair, model) -> dict:
    """The pair with FPFH never and always asked, on one thread: right, support, time."""
    import time

    from o3d_rpointhop import register
    from o3d_rpointhop.evaluation.metrics import rmse_3dmatch
    from o3d_rpointhop.evaluation.runner import thread_budget

    row = {"pair": f"{pair.scene} {pair.i}-{pair.j}", "benchmark": pair.benchmark}
    with thread_budget("one"), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for name, support in (("alone", 0.0), ("asked", 1.0)):
            start = time.perf_counter()
            result = register(
                pair.source,
                pair.target,
                model,
                global_method=_step(support),
                viewpoints="origin",
                random_state=0,
            )
            row[f"{name}_seconds"] = time.perf_counter() - start
            rmse = rmse_3dmatch(result.transformation, pair.truth, pair.information)
            row[f"{name}_registered"] = bool(rmse < 0.2)
            if name == "alone":  # the share the fallback compares with min_support
                row["support"] = result.support
    return row


def _table(rows: list[dict]) -> list[dict]:
    out = []
    for t in THRESHOLDS:
        entry = {"threshold": t}
        for bench in ("3DMatch", "3DLoMatch"):
            mine = [r for r in rows if r["benchmark"] == bench]
            asked = [r["support"] < t for r in mine]
            entry[bench] = sum(
                r["asked_registered"] if a else r["alone_registered"]
                for r, a in zip(mine, asked, strict=True)
            )
            entry[f"{bench}_asked"] = sum(asked)
            entry[f"{bench}_pairs"] = len(mine)
        out.append(entry)
    return out


def _chosen(table: list[dict]) -> float:
    best = max(e["3DMatch"] + e["3DLoMatch"] for e in table)
    return min(e["threshold"] for e in table if e["3DMatch"] + e["3DLoMatch"] == best)


def _markdown(table: list[dict], chosen: float) -> str:
    lines = [
        "# When to ask FPFH: the fallback's min_support on unseen training scenes",
        "",
        "Each training scene registered with a scene model fitted on the other three; "
        "pairs registered (official test) with FPFH asked where the model's support is "
        "under the threshold, and how many pairs asked it.",
        "",
        "| min_support | 3DMatch | 3DLoMatch | FPFH asked (3DMatch / 3DLoMatch) |",
        "|---|---|---|---|",
    ]
    for e in table:
        mark = " (chosen)" if e["threshold"] == chosen else ""
        lines.append(
            f"| {e['threshold']}{mark} | {e['3DMatch']} / {e['3DMatch_pairs']} | "
            f"{e['3DLoMatch']} / {e['3DLoMatch_pairs']} | "
            f"{e['3DMatch_asked']} / {e['3DLoMatch_asked']} |"
        )
    return "\n".join(lines) + "\n"


def main() -> None:
    from o3d_rpointhop.evaluation.provenance import run_provenance

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", default=None)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--output", default=str(RESULTS))
    args = parser.parse_args()
    models = _models(args.data)
    pairs = _pairs(args.data)
    rows = Parallel(n_jobs=args.jobs)(delayed(_run)(p, models[p.scene]) for p in pairs)
    table = _table(rows)
    chosen = _chosen(table)
    out = {
        "benchmark": "fallback_selection",
        "settings": {
            "thresholds": list(THRESHOLDS),
            "models": {s: m.training_scenes_ for s, m in models.items()},
            "rule": "most pairs registered; among equals the smallest threshold",
        },
        "table": table,
        "chosen": chosen,
        "records": rows,
        "provenance": run_provenance([], None),
    }
    output = Path(args.output)
    output.mkdir(parents=True, exist_ok=True)
    (output / "fallback_selection.json").write_text(json.dumps(out, indent=1) + "\n")
    (output / "fallback_selection.md").write_text(_markdown(table, chosen))
    print(_markdown(table, chosen))


if __name__ == "__main__":
    main()
