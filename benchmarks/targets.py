"""The speed targets table of docs/performance.md, from the benchmark result files.

Every number is a ratio of medians measured in one run against the peer of that run
(Open3D's FPFH, Open3D's recipe), read from ``benchmarks/results``:

* describing: ``scaling.json`` (``benchmarks/scaling.py``), both thread budgets;
* ``register()`` on objects: ``modelnet40_timing_sample_timings.json`` (one thread each)
  and ``modelnet40_timing_sample_all_timings.json`` (every core each): R-PointHop +
  RANSAC + point-to-plane ICP, ``register()``'s path for the object model, against
  Open3D's FPFH + RANSAC + ICP recipe, per-pair medians;
* ``register()`` on indoor scans: ``3dmatch_heldout_timing_sample[_all]_timings.json``
  (the scene model's defaults against the recipe at 5 cm); on real object scans (the
  bunny's and the dragon's): ``bunny[_all]_timings.json`` and ``bunny[_all].json``;
* Open3D's tutorial with R-PointHop features: ``open3d_tutorial.json``
  (``benchmarks/open3d_tutorial.py``);
* ``register_multiway``: ``multiway_timings.json``;
* start-up: ``startup.json``, measured by this script with ``--measure-startup``
  (``o3d-rpointhop --help``, ``import o3d_rpointhop`` and ``import open3d``, each in a
  fresh process, medians of five).

Writes ``benchmarks/results/targets.md`` and replaces the table between the
``<!-- targets:begin -->`` and ``<!-- targets:end -->`` lines of docs/performance.md.

    python benchmarks/targets.py [--measure-startup]
"""

from __future__ import annotations

import argparse
import itertools
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
DOC = ROOT / "docs" / "performance.md"
BEGIN, END = "<!-- targets:begin -->", "<!-- targets:end -->"


def _load(name: str) -> dict | None:
    path = RESULTS / name
    return json.loads(path.read_text()) if path.is_file() else None


def _verdict(values: list[float], target: float) -> str:
    met = [v <= target for v in values]
    if all(met):
        return "met"
    if not any(met):
        return f"missed (worst {max(values) / target:.2f}x the target)"
    return "met in part"


def _median_ratio(records: dict, method: str, peer: str) -> float:
    ours = statistics.median(r["seconds"] for r in records[method])
    theirs = statistics.median(r["seconds"] for r in records[peer])
    return ours / theirs


#: The timing files of a benchmark, by thread budget: ``<stem>_timings.json`` ran
#: with ``--threads one``, ``<stem>_all_timings.json`` with ``--threads all``.
BUDGETS = (("one", "one thread each", ""), ("all", "every core each", "_all"))


def _label(n: int) -> str:
    return f"{n // 1000}k" if n < 10**6 else f"{n // 10**6}M"


#: The descriptors the describing targets are reported for: scaling.py's method name
#: and the words of the row.
DESCRIBED = (
    ("rpointhop-object", "the object model (register()'s, 24-D)"),
    ("rpointhop-128", "the paper's model on 128 axes"),
)


def describing_rows() -> list[tuple[str, str, str]]:
    scaling = _load("scaling.json")
    if scaling is None:
        return []
    rows = []
    for (budget, words, _), (method, described) in itertools.product(BUDGETS, DESCRIBED):
        seconds = {
            (r["method"], r["points"]): r["seconds"]
            for r in scaling["rows"]
            if r.get("budget", "all") == budget
        }
        sizes = sorted({p for _, p in seconds})
        axes = [
            (n, seconds[(method, n)] / seconds[("fpfh", n)])
            for n in sizes
            if (method, n) in seconds and ("fpfh", n) in seconds
        ]
        if not axes:
            continue

        def target(n):
            return 0.7 if n < 200_000 else 0.5

        met = [_label(n) for n, r in axes if r <= target(n)]
        missed = [
            f"{_label(n)} ({r / target(n):.2f}x the target)" for n, r in axes if r > target(n)
        ]
        verdict = "; ".join(
            part
            for part in (
                f"met at {', '.join(met)}" if met else "",
                f"missed at {', '.join(missed)}" if missed else "",
            )
            if part
        )
        rows.append(
            (
                f"describing, {described}, at most 0.7x Open3D normals + FPFH at 2k and "
                f"20k points, 0.5x from 200k ({words})",
                " / ".join(f"{r:.2f}x" for _, r in axes)
                + f" at {' / '.join(_label(n) for n, _ in axes)}",
                verdict,
            )
        )
    peaks = {
        r["method"]: r["peak_rss_mb"]
        for r in scaling["rows"]
        if r["points"] == 10**6 and r.get("budget", "all") == "all"
    }
    for method, described in DESCRIBED:
        if method in peaks:
            rows.append(
                (
                    f"1M points within 2 GiB ({described}, every core)",
                    f"{peaks[method]:.0f} MiB",
                    _verdict([peaks[method]], 2048),
                )
            )
    return rows


def _pair_row(label, protocols, method, peer, target, names=None, show_names=True):
    """A target row for ``method`` against ``peer`` on every protocol of a timings file
    that ran it (``names``: those protocols, in order; default: all); None without
    any."""
    names = names or list(protocols)
    found = [
        (n, _median_ratio(protocols[n]["records"], method, peer))
        for n in names
        if n in protocols and method in protocols[n]["records"]
    ]
    if not found:
        return None
    text = " / ".join(f"{r:.2f}x" for _, r in found)
    if show_names:
        text += " (" + " / ".join(n for n, _ in found) + ")"
    return label, text, _verdict([r for _, r in found], target)


#: The real object scans of the bunny benchmark (``bunny[_all].json``): protocol and
#: the words of the row.
REAL_SCANS = (("scans", "the bunny's"), ("dragon", "the dragon's"))


def _successes(results: dict, protocol: str, method: str) -> tuple[int, int]:
    """The pairs a method placed on a protocol of a pair benchmark's results, of all."""
    summary = results["protocols"][protocol]["summary"][method]
    return round(summary["success_rate"] * summary["pairs"]), summary["pairs"]


def _placed(results: dict, protocol: str, method: str) -> str:
    """``placed / pairs`` of a method on a protocol of a pair benchmark's results."""
    return "{} / {}".format(*_successes(results, protocol, method))


def _real_scans_row(suffix: str, words: str):
    """``register()`` against the recipe on the bunny's and the dragon's scan pairs, with
    the pairs each places; None without the records."""
    timings, results = _load(f"bunny{suffix}_timings.json"), _load(f"bunny{suffix}.json")
    if timings is None or results is None:
        return None
    ours, peer = "rpointhop-ransac-icp", "fpfh-ransac-icp"
    found = [
        (protocol, name)
        for protocol, name in REAL_SCANS
        if protocol in timings["protocols"]
        and {ours, peer} <= set(timings["protocols"][protocol]["records"])
    ]
    if not found:
        return None
    ratios = [_median_ratio(timings["protocols"][p]["records"], ours, peer) for p, _ in found]
    text = " / ".join(f"{r:.2f}x" for r in ratios) + " (" + " / ".join(p for p, _ in found)
    text += "); placed " + " and ".join(_placed(results, p, ours) for p, _ in found)
    text += " (the recipe " + " and ".join(_placed(results, p, peer) for p, _ in found) + ")"
    pairs = ", ".join(
        f"{name} {results['protocols'][p]['summary'][ours]['pairs']} pairs" for p, name in found
    )
    label = f"`register()` on real scans ({pairs}) at most 1.0x the recipe ({words})"
    behind = [
        p for p, _ in found if _successes(results, p, ours)[0] < _successes(results, p, peer)[0]
    ]
    verdict = _verdict(ratios, 1.0)
    if behind:
        verdict += f" (time); fewer pairs placed than the recipe on {' and '.join(behind)}"
    return label, text, verdict


def register_rows() -> list[tuple[str, str, str]]:
    rows = []
    for _, words, suffix in BUDGETS:
        objects = _load(f"modelnet40_timing_sample{suffix}_timings.json")
        if objects is not None:
            rows.append(
                _pair_row(
                    "`register()` on ModelNet40 pairs at most 0.7x Open3D's FPFH + RANSAC + "
                    f"ICP recipe ({words})",
                    objects["protocols"],
                    "rpointhop-ransac-icp",
                    "fpfh-ransac-icp",
                    0.7,
                    names=["resampled", "resampled-noise", "resampled-partial"],
                )
            )
    for _, words, suffix in BUDGETS:
        scenes = _load(f"3dmatch_heldout_timing_sample{suffix}_timings.json")
        if scenes is None:
            continue
        rows.append(
            _pair_row(
                "`register()` on 3DMatch fragments (scene model) at most 1.0x the recipe "
                f"({words})",
                scenes["protocols"],
                "rpointhop-scene",
                "fpfh-ransac-icp-5cm",
                1.0,
            )
        )
        rows.append(
            _pair_row(
                "FPFH through this library's consensus + ICP on 3DMatch fragments, at "
                f"most 0.8x the recipe ({words})",
                scenes["protocols"],
                "fpfh-pipeline-consensus-icp",
                "fpfh-ransac-icp-5cm",
                0.8,
                show_names=False,
            )
        )
    for _, words, suffix in BUDGETS:
        row = _real_scans_row(suffix, words)
        if row is not None:
            rows.append(row)
    tutorial = _load("open3d_tutorial.json")
    if tutorial is not None:
        sets = {
            "bunny-neighbours": "the bunny's ring scans 45 deg apart",
            "bunny": "every bunny scan to bun000",
        }
        for (pairs, what), (_, words, _suffix) in itertools.product(sets.items(), BUDGETS):
            run = tutorial["runs"].get(f"{pairs}/{_}")
            if run is None:
                continue
            summary = run["summary"]
            name = tutorial.get("recommended", "object")
            if name not in summary:
                continue
            ours, fpfh = summary[name], summary["fpfh"]
            every = ours["placed"] == ours["runs"]
            rows.append(
                (
                    f"Open3D's tutorial with R-PointHop features ({name}) at most 1.0x FPFH's "
                    f"flow, every pair placed ({what}, {words})",
                    f"{ours['ratio_to_fpfh']:.2f}x; placed {ours['placed']} / {ours['runs']} "
                    f"runs (FPFH {fpfh['placed']} / {fpfh['runs']})",
                    "met" if ours["ratio_to_fpfh"] <= 1.0 and every else "missed",
                )
            )
    multiway = _load("multiway_timings.json")
    if multiway is not None:
        found = [
            (name, o["methods"]["rpointhop"]["seconds"] / o["methods"]["open3d-recipe"]["seconds"])
            for name, o in multiway["objects"].items()
        ]
        rows.append(
            (
                "`register_multiway` at most 0.5x Open3D's multiway recipe (every core each)",
                " / ".join(f"{name} {r:.2f}x" for name, r in found),
                _verdict([r for _, r in found], 0.5),
            )
        )
    return [row for row in rows if row is not None]


def _median_seconds(code: list[str], repeats: int = 5) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        subprocess.run(code, check=True, capture_output=True)
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def measure_startup() -> dict:
    from o3d_rpointhop.evaluation.provenance import descriptor_provenance

    python = sys.executable
    script = Path(python).with_name("o3d-rpointhop")
    return {
        "help_seconds": _median_seconds([str(script), "--help"]),
        "import_seconds": _median_seconds([python, "-c", "import o3d_rpointhop"]),
        "import_open3d_seconds": _median_seconds([python, "-c", "import open3d"]),
        # No descriptor runs: the record names the library and the command timed.
        "provenance": descriptor_provenance(
            {"startup": {"class": None, "timed": "o3d-rpointhop --help; import o3d_rpointhop"}},
            threads="default",
        ),
    }


def startup_rows() -> list[tuple[str, str, str]]:
    startup = _load("startup.json")
    if startup is None:
        return []
    help_s, ours, open3d = (
        startup["help_seconds"],
        startup["import_seconds"],
        startup["import_open3d_seconds"],
    )
    return [
        (
            "`o3d-rpointhop --help` under 1 s; `import o3d_rpointhop` faster than `import open3d`",
            f"{help_s:.2f} s; {ours:.2f} s against {open3d:.2f} s",
            "met" if help_s < 1.0 and ours < open3d else "missed",
        )
    ]


def table() -> str:
    rows = describing_rows() + register_rows() + startup_rows()
    lines = ["| target | measured | |", "|---|---|---|"]
    lines += [f"| {a} | {b} | {c} |" for a, b, c in rows]
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--measure-startup", action="store_true")
    args = parser.parse_args()
    if args.measure_startup:
        (RESULTS / "startup.json").write_text(json.dumps(measure_startup(), indent=1) + "\n")
    text = table()
    (RESULTS / "targets.md").write_text("# Speed targets (benchmarks/targets.py)\n\n" + text)
    doc = DOC.read_text()
    if BEGIN in doc and END in doc:
        head, rest = doc.split(BEGIN, 1)
        _, tail = rest.split(END, 1)
        DOC.write_text(f"{head}{BEGIN}\n{text}{END}{tail}")
    print(text, end="")


if __name__ == "__main__":
    main()
