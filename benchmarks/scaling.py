"""Descriptor time and peak memory from 2k to 1M points: R-PointHop against Open3D FPFH.

Every measurement runs in a fresh process (so its peak resident memory is its own),
interleaved R-PointHop / FPFH on the same cloud. The cloud is a synthetic CAD-like
object (``make_object``) sampled at each size. FPFH runs at its full-cost setting:
normals within 6x and histograms within 15x the point spacing, at most 30 and 100
neighbours. R-PointHop is the one-hop object model (``pretrained("object")``, 24-D,
what ``register()`` describes with), the paper's four-hop model projected on 128
principal axes (``pretrained(n_components=128)``) and on 32; its full 1624-D
descriptor is measured too up to 200k points (at 1M its float32 output alone is 6.5
GB). Two thread budgets, the same for both sides: one thread each (Open3D's
``set_max_threads(1)``, ``n_jobs=1``) and every core each (Open3D's default, the
descriptor's default ``n_jobs=None``). ``set_max_threads(1)`` is the way to one thread
that Open3D honours here: ``OMP_NUM_THREADS=1`` and threadpoolctl leave it on every
core, and pinning the process to one core (``taskset -c 0``) measures the same time
(``benchmarks/thread_budgets.py``, ``results/thread_budgets.md``).

Up to 20k points every size is measured in ``--rounds`` rounds (3 by default): each
round runs every method once, in that order, each in a fresh process, and a row keeps
the median of its rounds' medians (``round_seconds`` holds each). A burst of load from
elsewhere on the machine then falls on one round of one method, not on a whole row:
single runs of the 2k rows moved by up to a third between runs minutes apart.

Usage: python benchmarks/scaling.py [--sizes 2000 20000 200000 1000000]
       [--budgets one all] [--rounds 3] [--update] [--output DIR]
Writes DIR/scaling.json, DIR/scaling.md and DIR/scaling.png. ``--update`` measures only
the sizes and budgets given and keeps the file's other rows (the file records which
rows came from which run under ``"runs"``).
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path

from o3d_rpointhop.evaluation._common import machine_facts, peak_rss_mb
from o3d_rpointhop.evaluation.registry import entries

RESULTS = Path(__file__).resolve().parent / "results"
METHODS = {name: e.description for name, e in entries("scaling").items()}
FULL_MAX_POINTS = 200_000


def child(method: str, n: int, repeats: int, budget: str) -> None:
    """Run in a fresh process: describe the cloud ``repeats`` times, print JSON."""
    import numpy as np
    import open3d as o3d

    if budget == "one":
        o3d.utility.set_max_threads(1)

    from o3d_rpointhop import RPointHopTransformer
    from o3d_rpointhop._utils.geometry import point_spacing
    from o3d_rpointhop.datasets import make_object

    points = make_object(n, shape_seed=3, sample_seed=n)
    spacing = point_spacing(points)
    if method == "fpfh":
        search = o3d.geometry.KDTreeSearchParamHybrid

        def run():
            cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
            cloud.estimate_normals(search(radius=6 * spacing, max_nn=30))
            feature = o3d.pipelines.registration.compute_fpfh_feature(
                cloud, search(radius=15 * spacing, max_nn=100)
            )
            return np.asarray(feature.data).shape[::-1]

    else:
        if method == "rpointhop-object":
            model = RPointHopTransformer.pretrained("object")
        else:
            k = {"rpointhop-128": 128, "rpointhop-32": 32}.get(method)
            model = RPointHopTransformer.pretrained(n_components=k)
        model.set_params(n_jobs=1 if budget == "one" else None)

        def run():
            return model.transform(points).shape

    before = peak_rss_mb()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        shape = run()
        times.append(time.perf_counter() - start)
    print(
        json.dumps(
            {
                "method": method,
                "points": n,
                "budget": budget,
                "seconds": float(np.median(times)),
                "repeats": repeats,
                "peak_rss_mb": peak_rss_mb(),
                "rss_before_mb": before,
                "output_shape": list(shape),
            }
        )
    )


def measure(method: str, n: int, repeats: int, budget: str) -> dict:
    out = subprocess.run(
        [sys.executable, __file__, "--child", method, str(n), str(repeats), budget],
        check=True,
        capture_output=True,
        text=True,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def measure_rounds(methods: list[str], n: int, repeats: int, budget: str, rounds: int) -> list:
    """Every method ``rounds`` times, round by round (each run a fresh process); one
    row per method: the median of its rounds' medians, each round's in
    ``round_seconds``, the largest peak memory."""
    runs: dict[str, list[dict]] = {m: [] for m in methods}
    for _ in range(rounds):
        for method in methods:
            runs[method].append(measure(method, n, repeats, budget))
            print(json.dumps(runs[method][-1]), file=sys.stderr, flush=True)
    rows = []
    for found in runs.values():
        seconds = [r["seconds"] for r in found]
        rows.append(
            {
                **found[0],
                "seconds": float(statistics.median(seconds)),
                "round_seconds": seconds,
                "rounds": len(found),
                "peak_rss_mb": max(r["peak_rss_mb"] for r in found),
            }
        )
    return rows


def markdown(rows: list[dict], sizes: list[int]) -> str:
    """Per thread budget, seconds (and the ratio to FPFH in the same run) and peak
    memory per size."""
    budgets = sorted({r.get("budget", "all") for r in rows}, key=["one", "all"].index)
    return "\n".join(
        _table([r for r in rows if r.get("budget", "all") == b], sizes, b) for b in budgets
    )


def _table(rows: list[dict], sizes: list[int], budget: str) -> str:
    by = {(r["method"], r["points"]): r for r in rows}
    variants = [
        ("rpointhop-object", "object model (24-D)"),
        ("rpointhop-128", "128 axes"),
        ("rpointhop-32", "32 axes"),
        ("rpointhop-full", "1624-D"),
    ]
    lines = [
        f"{'One thread' if budget == 'one' else 'Every core'} each:",
        "",
        "| points | FPFH s | "
        + " | ".join(f"R-PointHop {label} s (ratio)" for _, label in variants)
        + " | peak MB: FPFH / "
        + " / ".join(label for _, label in variants)
        + " |",
        "|---" * (len(variants) + 3) + "|",
    ]
    for n in sizes:
        fpfh = by.get(("fpfh", n))
        if fpfh is None:
            continue
        cells, peaks = [], [f"{fpfh['peak_rss_mb']:.0f}"]
        for method, _ in variants:
            row = by.get((method, n))
            if row is None:
                cells.append("-")
                peaks.append("-")
                continue
            cells.append(f"{row['seconds']:.2f} (**{row['seconds'] / fpfh['seconds']:.2f}x**)")
            peaks.append(f"{row['peak_rss_mb']:.0f}")
        lines.append(
            f"| {n:,} | {fpfh['seconds']:.2f} | " + " | ".join(cells) + f" | {' / '.join(peaks)} |"
        )
    return "\n".join(lines) + "\n"


def plot(rows: list[dict], path: Path) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10, 4))
    for ax, key, label in zip(
        fig.subplots(1, 2), ("seconds", "peak_rss_mb"), ("seconds", "peak memory (MB)"), strict=True
    ):
        for method, name in METHODS.items():
            for budget, style in (("one", "--"), ("all", "-")):
                pts = sorted(
                    (r["points"], r[key])
                    for r in rows
                    if r["method"] == method and r.get("budget", "all") == budget
                )
                if pts:
                    label = f"{name} ({'one thread' if budget == 'one' else 'every core'})"
                    ax.loglog(*zip(*pts, strict=True), style, marker="o", label=label)
        ax.set_xlabel("points")
        ax.set_ylabel(label)
        ax.grid(True, which="both", alpha=0.3)
    fig.axes[0].legend(fontsize=7, loc="lower right")
    fig.suptitle("Descriptor cost against cloud size (log-log)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def provenance(budgets: list[str]) -> dict:
    """What made the run: each method's descriptor (the R-PointHop models by content
    hash) and the thread budgets the rows were measured on."""
    from o3d_rpointhop import RPointHopTransformer
    from o3d_rpointhop.evaluation.provenance import descriptor_provenance

    return descriptor_provenance(
        {
            "rpointhop-object": RPointHopTransformer.pretrained("object"),
            "rpointhop-128": RPointHopTransformer.pretrained(n_components=128),
            "rpointhop-32": RPointHopTransformer.pretrained(n_components=32),
            "rpointhop-full": RPointHopTransformer.pretrained(n_components=None),
            "fpfh": {
                "class": "open3d.pipelines.registration.compute_fpfh_feature",
                "params": "normals within 6x and histograms within 15x the point spacing, "
                "at most 30 / 100 neighbours",
            },
        },
        threads=" and ".join(budgets) + " (each row says which)",
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--sizes", type=int, nargs="+", default=[2000, 20000, 200000, 1000000])
    parser.add_argument("--budgets", nargs="+", choices=["one", "all"], default=["one", "all"])
    parser.add_argument("--rounds", type=int, default=3, help="rounds up to 20k points")
    parser.add_argument("--update", action="store_true", help="keep the file's other rows")
    parser.add_argument("--output", default=str(RESULTS))
    parser.add_argument("--child", nargs=4, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        child(args.child[0], int(args.child[1]), int(args.child[2]), args.child[3])
        return
    rows = []
    for budget in args.budgets:
        for n in args.sizes:
            repeats = 21 if n <= 2_000 else 5 if n <= 20_000 else 1
            rounds = max(1, args.rounds) if n <= 20_000 else 1
            methods = [m for m in METHODS if m != "rpointhop-full" or n <= FULL_MAX_POINTS]
            rows += measure_rounds(methods, n, repeats, budget, rounds)
    folder = Path(args.output)
    folder.mkdir(parents=True, exist_ok=True)
    facts = machine_facts()
    this_run = provenance(args.budgets)
    run = {"sizes": args.sizes, "budgets": args.budgets, "commit": this_run["commit"]}
    runs, sizes = [run], list(args.sizes)
    path = folder / "scaling.json"
    if args.update and path.is_file():
        before = json.loads(path.read_text())
        measured = {(n, b) for n in args.sizes for b in args.budgets}
        kept = [r for r in before["rows"] if (r["points"], r.get("budget", "all")) not in measured]
        rows = kept + rows
        first = {"commit": before["provenance"]["commit"], "note": before.get("remeasured")}
        runs = before.get("runs", [first]) + runs
        sizes = sorted({r["points"] for r in rows})
    result = {
        **{k: facts[k] for k in ("machine", "python", "open3d")},
        "methods": METHODS,
        "rows": rows,
        "provenance": this_run,
        "runs": runs,
    }
    path.write_text(json.dumps(result, indent=1))
    (folder / "scaling.md").write_text(markdown(rows, sizes))
    plot(rows, folder / "scaling.png")
    print(markdown(rows, sizes))


if __name__ == "__main__":
    main()
