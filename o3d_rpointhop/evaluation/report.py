"""Benchmark reports: JSON, markdown tables and plots, with timings kept apart.

A benchmark's numbers split in two: what the method found (errors, recall: the same on
every rerun with the same seed and libraries) and how long it took (different on every
run). :func:`write_report` writes the first to ``<stem>.json`` / ``<stem>.md`` and the
second to ``<stem>_timings.json`` / ``<stem>_timings.md``, so rerunning a benchmark
leaves the result files unchanged unless a result changed.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .methods import METHODS

__all__ = ["TIMING_KEYS", "split_timings", "markdown", "write_split", "write_report"]

#: Keys whose values are wall times or depend on the machine, wherever they occur.
TIMING_KEYS = frozenset(
    {
        "seconds",
        "seconds_per_pair",
        "median_seconds_per_pair",
        "fit_seconds",
        "machine",
        "thread_budget",
        "peak_memory_gib",
    }
)


def split_timings(results):
    """``(deterministic, timings)``: ``results`` without the :data:`TIMING_KEYS`, and a
    tree of the same shape holding only them (``None`` where there are none)."""
    if isinstance(results, dict):
        kept, timed = {}, {}
        for key, value in results.items():
            if key in TIMING_KEYS:
                timed[key] = value
                continue
            kept[key], sub = split_timings(value)
            if sub is not None:
                timed[key] = sub
        return kept, (timed or None)
    if isinstance(results, list):
        parts = [split_timings(v) for v in results]
        timed = [t for _, t in parts]
        return [k for k, _ in parts], (timed if any(t is not None for t in timed) else None)
    return results, None


_COLUMNS = (
    ("success_rate", "success", "{:.1%}"),
    ("success_rate_up_to_symmetry", "success up to symmetry", "{:.1%}"),
    ("mae_r", "MAE(R) deg", "{:.3f}"),
    ("mae_r_not_symmetric", "MAE(R) deg, symmetric flips left out", "{:.3f}"),
    ("rmse_r", "RMSE(R) deg", "{:.3f}"),
    ("mse_r", "MSE(R)", "{:.3f}"),
    ("mae_t", "MAE(t)", "{:.5f}"),
    ("rmse_t", "RMSE(t)", "{:.5f}"),
    ("median_rotation_error_deg", "median rot. err. deg", "{:.3f}"),
    ("mean_rotation_error_deg", "mean isotropic rot. err. deg", "{:.3f}"),
    ("mean_translation_error", "mean isotropic transl. err.", "{:.4f}"),
    ("chamfer", "modified Chamfer distance", "{:.6f}"),
    ("registration_recall", "registration recall (scene mean)", "{:.1%}"),
    ("registration_recall_pairs", "recall, pair mean", "{:.1%}"),
    ("recall_re_te", "recall by RE < 15 deg, TE < 30 cm", "{:.1%}"),
    ("precision", "precision of claimed results", "{:.1%}"),
    ("median_translation_error", "median transl. err.", "{:.4f}"),
    ("seconds_per_pair", "s per pair", "{:.3f}"),
)


def _table(summary: dict) -> list[str]:
    keys = [c for c in _COLUMNS if any(c[0] in s for s in summary.values())]
    lines = ["| method | " + " | ".join(c[1] for c in keys) + " |"]
    lines.append("|---" * (len(keys) + 1) + "|")
    for method, s in summary.items():
        cells = [
            "-" if s.get(c[0]) is None and c[0] in s else c[2].format(s[c[0]]) if c[0] in s else ""
            for c in keys
        ]
        lines.append(f"| {METHODS[method].description} | " + " | ".join(cells) + " |")
    return lines


def _scene_table(per_scene: dict, settings: dict) -> list[str]:
    """Registration recall per scene; scenes the R-PointHop model was fitted on marked."""
    seen = set(settings.get("model_training_scenes") or [])
    methods = list(per_scene)
    scenes = list(next(iter(per_scene.values())))
    lines = ["| scene | pairs | " + " | ".join(METHODS[m].description for m in methods) + " |"]
    lines.append("|---" * (len(methods) + 2) + "|")
    for scene in scenes:
        name = f"{scene} (a model of this run fitted on it)" if scene in seen else scene
        cells = [f"{per_scene[m][scene]['registration_recall']:.1%}" for m in methods]
        count = per_scene[methods[0]][scene]["pairs"]
        lines.append(f"| {name} | {count} | " + " | ".join(cells) + " |")
    return lines


def markdown(results: dict) -> str:
    """Markdown tables of a benchmark result."""
    lines = [f"# Benchmark: {results['dataset']}", ""]
    settings = results["settings"]
    lines.append(
        f"Python {settings['python']}, Open3D {settings['open3d']}, numpy "
        f"{settings['numpy']}; seed {settings['seed']}. Timings: {results['dataset']}"
        "_timings.md."
    )
    if "protocol" in settings:
        lines.append(
            f"Protocol: {settings['protocol']}; viewpoints given to the descriptors: "
            f"{settings.get('viewpoints')}."
        )
    if "model_file_bytes" in settings:
        lines.append(
            f"The benchmark's own R-PointHop model: "
            f"{settings['model_n_features_out']}-D descriptors, "
            f"{settings['model_file_bytes']:,} bytes on disk."
        )
    if "provenance" in results:
        lines += ["", *_provenance_table(results["provenance"])]
    for name, protocol in results["protocols"].items():
        lines += ["", f"## {name}", ""]
        if "description" in protocol:
            lines += [protocol["description"] + ".", ""]
        if "success" in protocol:
            lines += [f"Success: {protocol['success']}.", ""]
        if "fit_seconds" in protocol:
            lines += [
                f"Model fitted for this protocol on {protocol['fit_shapes']} shapes in "
                f"{protocol['fit_seconds']:.1f} s.",
                "",
            ]
        if "angles" in protocol:
            methods = list(next(iter(protocol["summary"].values())))
            lines.append(
                "| max angle (deg) | "
                + " | ".join(f"{METHODS[m].description}: MAE(R) / success" for m in methods)
                + " |"
            )
            lines.append("|---" * (len(methods) + 1) + "|")
            for angle, summ in protocol["summary"].items():
                cells = [f"{summ[m]['mae_r']:.2f} / {summ[m]['success_rate']:.0%}" for m in methods]
                lines.append(f"| {angle} | " + " | ".join(cells) + " |")
            continue
        lines += _table(protocol["summary"])
        if "summary_unseen_scenes" in protocol:
            count = next(iter(protocol["summary_unseen_scenes"].values()))["pairs"]
            lines += [
                "",
                f"On the scenes no model of the run was fitted on ({count} pairs; the "
                "leave-one-scene-out models never see the pair's own scene):",
                "",
                *_table(protocol["summary_unseen_scenes"]),
            ]
        if "per_scene" in protocol:
            lines += ["", *_scene_table(protocol["per_scene"], settings)]
        if "diagnostics" in protocol:
            lines += ["", *_diagnostics_table(protocol["diagnostics"])]
        if "paired" in protocol:
            lines += ["", *_paired_table(protocol["paired"])]
    return "\n".join(lines) + "\n"


def _descriptor_cell(descriptor: dict) -> str:
    if "per_scene" in descriptor:
        return "R-PointHop, one model fitted per held-out scene: " + ", ".join(
            f"{scene} {entry['sha256'][:12]}" for scene, entry in descriptor["per_scene"].items()
        )
    if descriptor.get("sha256"):
        return (
            f"{descriptor['class']}, model {descriptor['model']} "
            f"({descriptor['n_features_out']}-D, sha256 {descriptor['sha256'][:12]})"
        )
    return str(descriptor.get("class"))


def _provenance_table(provenance: dict) -> list[str]:
    """What produced the results: the library, its commit, and each method's descriptor."""
    commit = provenance["commit"]
    state = "unknown commit" if commit["id"] is None else f"commit {commit['id'][:12]}"
    if commit.get("modified"):
        state += " with local changes"
    lines = [
        f"Made by o3d-rpointhop {provenance['o3d_rpointhop']} ({state}), thread budget "
        f"{provenance['threads']}. Descriptors (full parameters in the JSON file):",
        "",
        "| method | descriptor |",
        "|---|---|",
    ]
    for name, entry in provenance["methods"].items():
        lines.append(f"| {name} | {_descriptor_cell(entry['descriptor'])} |")
    return lines


def _diagnostics_table(diagnostics: dict) -> list[str]:
    """The descriptors' matches and frames (``evaluation.diagnostics``)."""

    def cell(value, form):
        return "-" if value is None else form.format(value)

    lines = [
        "Descriptors on the clouds register() describes with them (feature-match recall: "
        "more than 5 % of the mutual matches within 0.1 m; medians over pairs; frames "
        "within 25 deg at true correspondences, means over pairs):",
        "",
        "| descriptor | feature-match recall | inlier ratio | inlier count | correct "
        "matches both ways | frames repeat | normals repeat | normal lines repeat |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, row in diagnostics.items():
        cells = [
            cell(row["feature_match_recall"], "{:.1%}"),
            cell(row["median_inlier_ratio"], "{:.1%}"),
            cell(row["median_inlier_count"], "{:.0f}"),
            cell(row["median_correct_matches"], "{:.0f}"),
            cell(row["frame_repeatability"], "{:.1%}"),
            cell(row["normal_repeatability"], "{:.1%}"),
            cell(row["normal_line_repeatability"], "{:.1%}"),
        ]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return lines


def _paired_table(paired: dict) -> list[str]:
    """McNemar's exact test for every two methods on the same pairs."""
    lines = [
        "Paired comparisons on the same pairs (McNemar's exact test: pairs only the first "
        "method registered, only the second, two-sided p-value; below 0.05 the difference "
        "is unlikely to be chance):",
        "",
        "| first | second | first only | second only | p |",
        "|---|---|---|---|---|",
    ]
    for key, test in paired.items():
        first, second = key.split(" vs ")
        lines.append(
            f"| {first} | {second} | {test['a_only']} | {test['b_only']} | {test['p_value']:.3g} |"
        )
    return lines


def _plots(results: dict, folder: Path, stem: str) -> list[str]:
    from ..plotting import require_matplotlib

    figure_class = require_matplotlib()

    written = []
    bars = {n: p for n, p in results["protocols"].items() if "angles" not in p}
    metric = "registration_recall" if results["dataset"] == "3dmatch" else "success_rate"
    if bars:
        methods = list(next(iter(bars.values()))["summary"])
        fig = figure_class(figsize=(max(7, 1.6 * len(bars) + 4), 4))
        ax = fig.subplots()
        width = 0.8 / len(methods)
        for k, method in enumerate(methods):
            values = [p["summary"][method].get(metric, np.nan) for p in bars.values()]
            ax.bar(np.arange(len(bars)) + k * width, values, width, label=method)
        ax.set_xticks(np.arange(len(bars)) + 0.4 - width / 2, list(bars), rotation=15)
        ax.set_ylabel(metric.replace("_", " "))
        ax.set_ylim(0, 1.05)
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
        ax.set_title(f"{results['dataset']}: {metric.replace('_', ' ')} per protocol")
        fig.tight_layout()
        path = folder / f"{stem}_{metric}.png"
        fig.savefig(path, dpi=110)
        written.append(str(path))
    if results["dataset"] == "3dmatch":
        written += _overlap_plot(results, figure_class, folder, stem)
    for name, protocol in results["protocols"].items():
        if "angles" not in protocol:
            continue
        angles = protocol["angles"]
        methods = list(protocol["summary"][str(angles[0])])
        fig = figure_class(figsize=(16, 3.6))
        axes = fig.subplots(1, 4)
        for ax, (key, label) in zip(
            axes,
            (
                ("rmse_r", "RMSE(R) deg"),
                ("mae_r", "MAE(R) deg"),
                ("rmse_t", "RMSE(t)"),
                ("mae_t", "MAE(t)"),
            ),
            strict=True,
        ):
            for method in methods:
                ax.plot(
                    angles,
                    [protocol["summary"][str(a)][method][key] for a in angles],
                    marker="o",
                    label=method,
                )
            ax.set_xlabel("max rotation angle (deg)")
            ax.set_ylabel(label)
        axes[0].legend(fontsize=7)
        fig.suptitle(f"{results['dataset']}: error against the largest rotation angle")
        fig.tight_layout()
        path = folder / f"{stem}_{name}.png"
        fig.savefig(path, dpi=110)
        written.append(str(path))
    return written


def timings_markdown(results: dict) -> str:
    """Markdown table of the wall times: seconds per pair, per protocol and method."""
    settings = results["settings"]
    lines = [f"# Benchmark timings: {results['dataset']}", ""]
    budget = settings.get("thread_budget")
    threads = f"; {'one thread' if budget == 'one' else 'every core'} each" if budget else ""
    lines += [f"Machine: {settings.get('machine', '?')}{threads}; seed {settings['seed']}.", ""]
    medians = any(
        "median_seconds_per_pair" in s
        for p in results["protocols"].values()
        if "angles" not in p
        for s in p["summary"].values()
    )
    if medians:
        lines += ["| protocol | method | s per pair (mean) | median s per pair |"]
        lines += ["|---|---|---|---|"]
    else:
        lines += ["| protocol | method | s per pair |", "|---|---|---|"]
    for name, protocol in results["protocols"].items():
        summaries = protocol["summary"]
        if "angles" in protocol:  # one summary per angle: the mean over the angles
            methods = list(next(iter(summaries.values())))
            per = {
                m: np.mean([s[m]["seconds_per_pair"] for s in summaries.values()]) for m in methods
            }
            median = dict.fromkeys(methods)
        else:
            per = {m: s["seconds_per_pair"] for m, s in summaries.items()}
            median = {m: s.get("median_seconds_per_pair") for m, s in summaries.items()}
        for method, seconds in per.items():
            row = f"| {name} | {METHODS[method].description} | {seconds:.3f} |"
            if medians:
                row += " - |" if median[method] is None else f" {median[method]:.3f} |"
            lines.append(row)
        if "fit_seconds" in protocol:
            lines.append(f"| {name} | model fit | {protocol['fit_seconds']:.1f} (total) |")
    return "\n".join(lines) + "\n"


#: Overlap bins of the recall-against-overlap plot (3DLoMatch is below 0.3).
OVERLAP_BINS = (0.1, 0.2, 0.3, 0.5, 0.7, 1.0)


def _overlap_plot(results: dict, figure_class, folder: Path, stem: str) -> list[str]:
    """Registration recall against the pairs' overlap, both benchmarks pooled."""
    records: dict[str, list] = {}
    for protocol in results["protocols"].values():
        for method, recs in protocol.get("records", {}).items():
            records.setdefault(method, []).extend(recs)
    if not records:
        return []
    fig = figure_class(figsize=(7, 4))
    ax = fig.subplots()
    edges = np.array(OVERLAP_BINS)
    centres = 0.5 * (edges[:-1] + edges[1:])
    for method, recs in records.items():
        overlap = np.array([r["overlap"] if r["overlap"] is not None else np.nan for r in recs])
        hit = np.array([r["registered"] for r in recs], dtype=float)
        which = np.digitize(overlap, edges) - 1
        recall = [
            hit[which == b].mean() if np.any(which == b) else np.nan for b in range(len(centres))
        ]
        ax.plot(centres, recall, marker="o", label=METHODS[method].description)
    ax.set_xlabel("overlap (gt_overlap.log)")
    ax.set_ylabel("registration recall")
    ax.set_ylim(0, 1.05)
    ax.legend(fontsize=7, loc="lower right")
    ax.set_title("3DMatch + 3DLoMatch: recall against overlap")
    fig.tight_layout()
    path = folder / f"{stem}_recall_vs_overlap.png"
    fig.savefig(path, dpi=110)
    return [str(path)]


def write_split(
    results: dict, folder: Path, stem: str, markdown_of=None, timings_markdown_of=None
) -> list[str]:
    """Write ``<stem>.json`` without the timings (unchanged by a rerun) and
    ``<stem>_timings.json`` with them, in ``folder`` (made if missing); return the
    paths. ``markdown_of`` renders the results as ``<stem>.md``, ``timings_markdown_of``
    their wall times as ``<stem>_timings.md`` (each only when given)."""
    kept, timed = split_timings(results)
    texts = {f"{stem}.json": json.dumps(kept, indent=1, default=float) + "\n"}
    if markdown_of is not None:
        texts[f"{stem}.md"] = markdown_of(kept)
    texts[f"{stem}_timings.json"] = json.dumps(timed, indent=1, default=float) + "\n"
    if timings_markdown_of is not None:
        texts[f"{stem}_timings.md"] = timings_markdown_of(results)
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    for name, text in texts.items():
        (folder / name).write_text(text)
    return [str(folder / name) for name in texts]


def write_report(results: dict, output_dir, stem: str | None = None) -> list[str]:
    """Write the results apart from their timings (:func:`write_split`), and the plots;
    return the paths."""
    folder = Path(output_dir)
    folder.mkdir(parents=True, exist_ok=True)
    stem = stem or results["dataset"]
    written = write_split(results, folder, stem, markdown, timings_markdown)
    return [*written, *_plots(split_timings(results)[0], folder, stem)]
