"""How far a claimed result can be trusted by its support, on 3DMatch *training* scenes.

``RegistrationResult.support`` is the share of the global step's matches its estimate
explains. Every official pair (non-consecutive fragments) of the scenes the shipped
scene model was fitted on (its ``training_scenes_``) is registered by the scene model
through ``register()`` and by FPFH through the consensus at 4096 points (the benchmark
methods ``rpointhop-scene`` and ``fpfh-pipeline-consensus-icp-4096``, the sensor at
the origin), and for every threshold of :data:`THRESHOLDS` the table counts the claimed
results (converged, not ambiguous) whose support reaches it: how many, how many right
(the official 0.2 m error), and how many right claims it drops. No held-out scene is
touched.

The rule: the largest threshold at which the scene model's 3DMatch claims keep every
right result (docs/registration.md, "How far to trust a result").

Writes ``benchmarks/results/support_threshold.{json,md}``.

Usage: python benchmarks/support_threshold.py [--data PATH] [--jobs N]
"""

from __future__ import annotations

import argparse
import json
import warnings
from pathlib import Path

from joblib import Parallel, delayed

RESULTS = Path(__file__).resolve().parent / "results"
METHODS = ("rpointhop-scene", "fpfh-pipeline-consensus-icp-4096")
THRESHOLDS = (0.0, 0.005, 0.0075, 0.01, 0.0125, 0.015, 0.02, 0.03)


def _training_pairs(data):
    from o3d_rpointhop import RPointHopTransformer
    from o3d_rpointhop.datasets import load_3dmatch_pairs
    from o3d_rpointhop.evaluation.threedmatch import official_pairs

    seen = set(RPointHopTransformer.pretrained("scene").training_scenes_)
    return [p for p in official_pairs(load_3dmatch_pairs(data)) if p.scene in seen]


def _run(pair) -> list[dict]:
    """Both methods on one pair, on one thread each: right, claimed, support."""
    import numpy as np

    from o3d_rpointhop.evaluation.metrics import rmse_3dmatch
    from o3d_rpointhop.evaluation.runner import run_method, thread_budget

    rows = []
    with thread_budget("one"), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for method in METHODS:
            run = run_method(
                method,
                pair.source,
                pair.target,
                descriptor=None,
                voxel=0.05,
                viewpoints=(np.zeros(3), np.zeros(3)),
            )
            rmse = rmse_3dmatch(run.transformation, pair.truth, pair.information)
            rows.append(
                {
                    "method": method,
                    "pair": f"{pair.scene} {pair.i}-{pair.j}",
                    "benchmark": pair.benchmark,
                    "registered": bool(rmse < 0.2),
                    "claimed": bool(run.claimed),
                    "support": run.result.support,
                }
            )
    return rows


def _table(records: list[dict]) -> list[dict]:
    """Per method, benchmark and threshold: claims kept, right among them, right lost."""
    out = []
    for method in METHODS:
        for bench in ("3DMatch", "3DLoMatch"):
            claims = [
                r
                for r in records
                if r["method"] == method and r["benchmark"] == bench and r["claimed"]
            ]
            right = sum(r["registered"] for r in claims)
            for t in THRESHOLDS:
                kept = [r for r in claims if r["support"] >= t]
                kept_right = sum(r["registered"] for r in kept)
                out.append(
                    {
                        "method": method,
                        "benchmark": bench,
                        "threshold": t,
                        "claimed": len(kept),
                        "right": kept_right,
                        "precision": kept_right / len(kept) if kept else None,
                        "right_lost": right - kept_right,
                    }
                )
    return out


def _chosen(table: list[dict]) -> float:
    """The rule: the largest threshold that drops no right 3DMatch claim of the scene
    model."""
    return max(
        r["threshold"]
        for r in table
        if r["method"] == METHODS[0] and r["benchmark"] == "3DMatch" and r["right_lost"] == 0
    )


def _markdown(table: list[dict], chosen: float, n_pairs: dict) -> str:
    lines = [
        "# Support of claimed results (3DMatch training scenes)",
        "",
        f"Official pairs of the scene model's training scenes: {n_pairs['3DMatch']} 3DMatch, "
        f"{n_pairs['3DLoMatch']} 3DLoMatch. A claim is a result converged and not "
        "ambiguous; kept when its support reaches the threshold. Chosen (the largest "
        f"threshold that drops no right 3DMatch claim of the scene model): **{chosen}**.",
        "",
        "| method | benchmark | threshold | claims | right | precision | right claims dropped |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in table:
        precision = "-" if r["precision"] is None else f"{r['precision']:.1%}"
        lines.append(
            f"| {r['method']} | {r['benchmark']} | {r['threshold']} | {r['claimed']} | "
            f"{r['right']} | {precision} | {r['right_lost']} |"
        )
    return "\n".join(lines) + "\n"


def main() -> None:
    from o3d_rpointhop.datasets import data_home
    from o3d_rpointhop.evaluation.provenance import run_provenance

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=None, help="the data folder (default: data_home())")
    parser.add_argument("--jobs", type=int, default=1, help="pairs run at once, one thread each")
    args = parser.parse_args()
    pairs = _training_pairs(args.data or data_home())
    rows = Parallel(n_jobs=args.jobs)(delayed(_run)(p) for p in pairs)
    records = [r for pair_rows in rows for r in pair_rows]
    table = _table(records)
    chosen = _chosen(table)
    n_pairs = {b: sum(p.benchmark == b for p in pairs) for b in ("3DMatch", "3DLoMatch")}
    out = {
        "pairs": n_pairs,
        "chosen_threshold": chosen,
        "table": table,
        "records": records,
        "provenance": run_provenance(list(METHODS), None),
    }
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "support_threshold.json").write_text(json.dumps(out, indent=1))
    (RESULTS / "support_threshold.md").write_text(_markdown(table, chosen, n_pairs))
    print(_markdown(table, chosen, n_pairs))


if __name__ == "__main__":
    main()
