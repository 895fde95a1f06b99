"""Run benchmark protocols and write their JSON, markdown tables and plots."""

from __future__ import annotations

import json
import platform
import time
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from .._progress import progress_bar
from ..open3d_interop import to_point_cloud
from ..registration.settings import resolve_voxel_size
from ..rpointhop import RPointHopTransformer, default_descriptor
from ..transforms import rotation_error_deg, translation_error
from .methods import METHODS, run_method
from .metrics import is_symmetry, match_inlier_ratio, pair_errors, rmse_3dmatch, summarize
from .protocols import PROTOCOLS, make_pairs

__all__ = [
    "MODELNET40_PROTOCOLS",
    "ANGLE_SWEEP",
    "Progress",
    "run_modelnet40",
    "run_bunny",
    "run_3dmatch",
    "write_report",
]

MODELNET40_PROTOCOLS = {
    **PROTOCOLS,
    "paper-unseen-classes": "as 'paper', with a model fitted on classes 0-19 only and test "
    "shapes from classes 20-39",
    "angle-sweep": "as 'paper', with the largest Euler angle swept from 0 to 180 deg",
}
BUNNY_PROTOCOLS = {
    "scans": "real range scans registered to bun000, ground truth from bun.conf",
    "paper": "the paper's: each scan against a differently sampled copy of itself (2048 "
    "random points each), moved by Euler angles in [0, 45] deg and a translation in "
    "[-0.5, 0.5] m",
}
ANGLE_SWEEP = (0, 15, 30, 45, 60, 90, 120, 150, 180)
SWEEP_METHODS = ("rpointhop-svd", "rpointhop-ransac-icp", "fpfh-ransac-icp", "icp")
# Voxel of Open3D's FPFH recipe for unit-sphere objects (its tutorial's value).
MODELNET40_FPFH_VOXEL = 0.05


class Progress:
    """A ``tqdm`` bar on stderr for a benchmark (shown when enabled and stderr is a
    terminal, or when ``enabled`` is True and asked explicitly by the caller)."""

    def __init__(self, total: int, label: str, enabled: bool = True) -> None:
        self.bar = progress_bar(
            max(total, 1), desc=label, unit="pair", enabled=None if enabled else False
        )

    def step(self, note: str = "") -> None:
        if self.bar is not None:
            self.bar.set_postfix_str(note[:30], refresh=False)
            self.bar.update(1)
            if self.bar.n >= self.bar.total:
                self.bar.close()


def _machine() -> dict:
    import os

    import open3d

    return {
        "machine": f"{platform.machine()}, {len(os.sched_getaffinity(0))} cores",
        "python": platform.python_version(),
        "open3d": open3d.__version__,
        "numpy": np.__version__,
    }


def _model_facts(model: RPointHopTransformer) -> dict:
    """Size of the model's file and of its descriptors (the 'green' figures)."""
    import tempfile

    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "model.npz"
        model.save(path)
        size = path.stat().st_size
    return {
        "model_file_bytes": size,
        "model_n_features_out": int(model.n_features_out_),
        "model_params": model.get_params(),
    }


def _check_methods(methods: Iterable[str]) -> list[str]:
    methods = list(methods)
    unknown = [m for m in methods if m not in METHODS]
    if unknown:
        raise ValueError(f"unknown methods {unknown}; choose from {sorted(METHODS)}")
    return methods


def _evaluate(pairs, methods, model, voxel_of, seed, progress, shapes=None, tol=(5.0, 0.05)):
    """Run every method on every pair; return {method: summary} and per-pair records.

    ``shapes`` (the whole shape of each pair) enables the symmetry check; ``tol`` is the
    success threshold (rotation in degrees, translation in the data's unit).
    """
    summaries, records = {}, {}
    voxels = [voxel_of(pair) for pair in pairs]  # once per pair, not once per method
    for method in methods:
        recs = []
        for k, pair in enumerate(pairs):
            estimate, seconds = run_method(
                method, pair.source, pair.target, descriptor=model, voxel=voxels[k], seed=seed
            )
            rec = {**pair_errors(estimate, pair.truth), "seconds": seconds, "pair": pair.name}
            if shapes is not None:
                rec["symmetric"] = is_symmetry(estimate, pair.truth, shapes[k])
            recs.append(rec)
            progress.step(method)
        summaries[method] = summarize(recs, *tol)
        records[method] = recs
    return summaries, records


def run_modelnet40(
    protocols: Iterable[str],
    methods: Iterable[str],
    *,
    data=None,
    seed: int = 0,
    max_shapes: int | None = None,
    model: RPointHopTransformer | None = None,
    progress: bool = True,
) -> dict:
    """ModelNet40 registration protocols (see :data:`MODELNET40_PROTOCOLS`).

    Parameters
    ----------
    protocols, methods : iterables of str
    data : path, default=None
        Official ``modelnet40_ply_hdf5_2048`` folder or the shared-data layout.
    max_shapes : int, default=None
        Use only the first shapes of each test split (quick runs).
    model : RPointHopTransformer, default=None
        ``None`` is the pretrained model (fitted on all classes of the train subset).

    Returns
    -------
    dict
        ``{"dataset", "settings", "protocols": {name: {"summary": {method: {...}},
        "records": {...}}}}``; the angle sweep stores one summary per angle.
    """
    from ..datasets import load_modelnet40

    protocols = list(protocols)
    unknown = [p for p in protocols if p not in MODELNET40_PROTOCOLS]
    if unknown:
        raise ValueError(f"unknown protocols {unknown}; choose from {sorted(MODELNET40_PROTOCOLS)}")
    methods = _check_methods(methods)
    train = load_modelnet40("train", data)
    test = load_modelnet40("test", data)
    model = model if model is not None else default_descriptor()
    out = {
        "dataset": "modelnet40",
        "source": test.source,
        "settings": {
            "seed": seed,
            "test_shapes": len(test) if max_shapes is None else min(max_shapes, len(test)),
            "fpfh_voxel": MODELNET40_FPFH_VOXEL,
            "success": "rotation error < 5 deg and translation error < 0.05",
            **_model_facts(model),
            **_machine(),
        },
        "protocols": {},
    }
    for protocol in protocols:
        shapes, protocol_model = test.points, model
        fit_seconds = None
        if protocol == "paper-unseen-classes":
            shapes = test.points[test.labels >= 20]
            seen = train.points[train.labels < 20]
            start = time.perf_counter()
            protocol_model = RPointHopTransformer(**model.get_params()).fit(list(seen))
            fit_seconds = time.perf_counter() - start
        if max_shapes is not None:
            shapes = shapes[:max_shapes]
        if protocol == "angle-sweep":
            sweep_methods = [m for m in methods if m in SWEEP_METHODS] or methods
            bar = Progress(len(ANGLE_SWEEP) * len(sweep_methods) * len(shapes), protocol, progress)
            per_angle = {}
            for angle in ANGLE_SWEEP:
                pairs = make_pairs(shapes, "paper", seed, max_angle_deg=angle)
                per_angle[str(angle)], _ = _evaluate(
                    pairs, sweep_methods, model, lambda p: MODELNET40_FPFH_VOXEL, seed, bar
                )
            out["protocols"][protocol] = {"angles": list(ANGLE_SWEEP), "summary": per_angle}
            continue
        base = "paper" if protocol == "paper-unseen-classes" else protocol
        pairs = make_pairs(shapes, base, seed)
        bar = Progress(len(methods) * len(pairs), protocol, progress)
        summary, records = _evaluate(
            pairs, methods, protocol_model, lambda p: MODELNET40_FPFH_VOXEL, seed, bar, shapes
        )
        out["protocols"][protocol] = {
            "description": MODELNET40_PROTOCOLS[protocol],
            "summary": summary,
            "records": records,
        }
        if fit_seconds is not None:
            out["protocols"][protocol]["fit_seconds"] = fit_seconds
            out["protocols"][protocol]["fit_shapes"] = int(len(seen))
    return out


def run_bunny(
    protocols: Iterable[str],
    methods: Iterable[str],
    *,
    data=None,
    seed: int = 0,
    model: RPointHopTransformer | None = None,
    progress: bool = True,
) -> dict:
    """Stanford Bunny: real scan pairs with ``bun.conf`` poses, and the paper's protocol.

    ``"scans"``: every other scan registered to ``bun000`` (success: < 2 deg, < 2 mm).
    ``"paper"``: each scan against a differently sampled copy of itself (2048 random
    points each) moved by Euler angles in [0, 45] deg and a translation in
    [-0.5, 0.5] m, as in the paper (success: < 5 deg, < 5 mm).
    """
    from scipy.spatial.transform import Rotation

    from ..datasets.bunny import BUNNY_SCANS, load_bunny
    from .protocols import Pair

    methods = _check_methods(methods)
    model = model if model is not None else default_descriptor()
    scans = load_bunny(BUNNY_SCANS, data)
    out = {
        "dataset": "bunny",
        "settings": {"seed": seed, **_model_facts(model), **_machine()},
        "protocols": {},
    }
    rng = np.random.default_rng(seed)

    def resolution(pair):
        return resolve_voxel_size(
            to_point_cloud(pair.source), to_point_cloud(pair.target), "auto", 2048
        )[0]

    for protocol in protocols:
        if protocol == "scans":
            target = scans["bun000"]
            pairs = [
                Pair(s.points, target.points, s.relative_pose(target), s.points, name)
                for name, s in scans.items()
                if name != "bun000"
            ]
            tol = (2.0, 0.002)
        elif protocol == "paper":
            pairs = []
            for name, s in scans.items():
                pick = rng.permutation(len(s.points))
                target, truth_src = s.points[pick[:2048]], s.points[pick[2048:4096]]
                rot = Rotation.from_euler("zyx", rng.uniform(0, 45, 3), degrees=True).as_matrix()
                shift = rng.uniform(-0.5, 0.5, 3)
                truth = np.eye(4)
                truth[:3, :3], truth[:3, 3] = rot.T, -rot.T @ shift
                pairs.append(Pair(truth_src @ rot.T + shift, target, truth, truth_src, name))
            tol = (5.0, 0.005)
        else:
            raise ValueError(f"unknown bunny protocol {protocol!r}; choose 'scans' or 'paper'")
        bar = Progress(len(methods) * len(pairs), f"bunny {protocol}", progress)
        summaries, records = _evaluate(pairs, methods, model, resolution, seed, bar, tol=tol)
        out["protocols"][protocol] = {
            "description": BUNNY_PROTOCOLS[protocol],
            "success": f"rotation error < {tol[0]} deg and translation error < {tol[1] * 1000} mm",
            "summary": summaries,
            "records": records,
        }
    return out


def run_3dmatch(
    methods: Iterable[str],
    *,
    data=None,
    seed: int = 0,
    model: RPointHopTransformer | None = None,
    progress: bool = True,
    max_pairs: int | None = None,
) -> dict:
    """3DMatch / 3DLoMatch fragment pairs with official ground truth.

    ``max_pairs``: a seeded random sample of at most this many pairs per benchmark
    (``None``: every pair).

    Registration recall: share of pairs whose official error (from ``gt.info``) is below
    0.2 m. Feature-match recall: share of pairs where more than 5 % of the mutual
    nearest-descriptor matches (on the registration's downsampled clouds) lie within
    0.1 m of each other under the ground truth.
    """
    from ..datasets.threedmatch import load_3dmatch_pairs
    from ..fpfh import FPFHTransformer
    from ..registration.context import RegistrationContext

    methods = _check_methods(methods)
    model = model if model is not None else default_descriptor()
    pairs = load_3dmatch_pairs(data)
    if max_pairs is not None:
        rng = np.random.default_rng(seed)
        picked = []
        for bench in ("3DMatch", "3DLoMatch"):
            these = [p for p in pairs if p.benchmark == bench]
            keep = np.sort(rng.permutation(len(these))[:max_pairs])
            picked += [these[k] for k in keep]
        pairs = picked
    out = {
        "dataset": "3dmatch",
        "settings": {
            "seed": seed,
            "pairs_per_benchmark": "all" if max_pairs is None else f"at most {max_pairs}",
            **_model_facts(model),
            **_machine(),
        },
        "protocols": {},
    }
    bar = Progress(len(methods) * len(pairs) + 2 * len(pairs), "3dmatch", progress)
    descriptors = {"rpointhop": model, "fpfh": FPFHTransformer(radius="auto", normal_radius="auto")}
    fmr = {name: [] for name in descriptors}
    voxels = {}  # the resolution register() picks, per pair
    for pair in pairs:
        context = RegistrationContext(pair.source, pair.target)
        voxels[id(pair)] = context.voxel_size
        for name, descriptor in descriptors.items():
            fmr[name].append({
                "pair": f"{pair.scene} {pair.i}-{pair.j}",
                "benchmark": pair.benchmark,
                "inlier_ratio": match_inlier_ratio(context, descriptor, pair.truth),
            })  # fmt: skip
            bar.step(f"fmr {name}")
    for bench in ("3DMatch", "3DLoMatch"):
        chosen = [p for p in pairs if p.benchmark == bench]
        if not chosen:
            continue
        summaries, records = {}, {}
        for method in methods:
            recs = []
            for pair in chosen:
                estimate, seconds = run_method(
                    method, pair.source, pair.target, descriptor=model,
                    voxel=voxels[id(pair)], seed=seed,
                )  # fmt: skip
                rmse = rmse_3dmatch(estimate, pair.truth, pair.information)
                recs.append({
                    "pair": f"{pair.scene} {pair.i}-{pair.j}", "overlap": pair.overlap,
                    "rmse": rmse, "registered": rmse < 0.2, "seconds": seconds,
                    "rotation_error_deg": rotation_error_deg(estimate, pair.truth),
                    "translation_error": translation_error(estimate, pair.truth),
                })  # fmt: skip
                bar.step(method)
            column = {key: [r[key] for r in recs] for key in recs[0]}
            summaries[method] = {
                "pairs": len(recs),
                "registration_recall": float(np.mean(column["registered"])),
                "median_rotation_error_deg": float(np.median(column["rotation_error_deg"])),
                "median_translation_error": float(np.median(column["translation_error"])),
                "seconds_per_pair": float(np.mean(column["seconds"])),
            }
            records[method] = recs
        feature_recall = {
            name: float(
                np.mean([r["inlier_ratio"] > 0.05 for r in rows if r["benchmark"] == bench])
            )
            for name, rows in fmr.items()
        }
        out["protocols"][bench] = {
            "summary": summaries,
            "feature_match_recall": feature_recall,
            "records": records,
            "inlier_ratios": fmr,
        }
    return out


# --------------------------------------------------------------------------- reports
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
    ("registration_recall", "registration recall", "{:.1%}"),
    ("median_translation_error", "median transl. err.", "{:.4f}"),
    ("seconds_per_pair", "s per pair", "{:.3f}"),
)


def _table(summary: dict) -> list[str]:
    keys = [c for c in _COLUMNS if any(c[0] in s for s in summary.values())]
    lines = ["| method | " + " | ".join(c[1] for c in keys) + " |"]
    lines.append("|---" * (len(keys) + 1) + "|")
    for method, s in summary.items():
        cells = [c[2].format(s[c[0]]) if c[0] in s else "" for c in keys]
        lines.append(f"| {METHODS[method].description} | " + " | ".join(cells) + " |")
    return lines


def markdown(results: dict) -> str:
    """Markdown tables of a benchmark result."""
    lines = [f"# Benchmark: {results['dataset']}", ""]
    settings = results["settings"]
    lines.append(
        f"Machine: {settings['machine']}; Python {settings['python']}, Open3D "
        f"{settings['open3d']}, numpy {settings['numpy']}; seed {settings['seed']}."
    )
    if "model_file_bytes" in settings:
        lines.append(
            f"R-PointHop model: {settings['model_n_features_out']}-D descriptors, "
            f"{settings['model_file_bytes']:,} bytes on disk."
        )
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
            lines.append("| max angle (deg) | " + " | ".join(
                f"{METHODS[m].description}: MAE(R) / success" for m in methods) + " |")  # fmt: skip
            lines.append("|---" * (len(methods) + 1) + "|")
            for angle, summ in protocol["summary"].items():
                cells = [f"{summ[m]['mae_r']:.2f} / {summ[m]['success_rate']:.0%}" for m in methods]
                lines.append(f"| {angle} | " + " | ".join(cells) + " |")
            continue
        lines += _table(protocol["summary"])
        if "feature_match_recall" in protocol:
            fmr = ", ".join(f"{k} {v:.1%}" for k, v in protocol["feature_match_recall"].items())
            lines += ["", f"Feature-match recall (tau1 0.1 m, tau2 0.05): {fmr}."]
    return "\n".join(lines) + "\n"


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
    for name, protocol in results["protocols"].items():
        if "angles" not in protocol:
            continue
        angles = protocol["angles"]
        methods = list(protocol["summary"][str(angles[0])])
        fig = figure_class(figsize=(16, 3.6))
        axes = fig.subplots(1, 4)
        for ax, (key, label) in zip(
            axes,
            (("rmse_r", "RMSE(R) deg"), ("mae_r", "MAE(R) deg"), ("rmse_t", "RMSE(t)"),
             ("mae_t", "MAE(t)")),
            strict=True,
        ):  # fmt: skip
            for method in methods:
                ax.plot(angles, [protocol["summary"][str(a)][method][key] for a in angles],
                        marker="o", label=method)  # fmt: skip
            ax.set_xlabel("max rotation angle (deg)")
            ax.set_ylabel(label)
        axes[0].legend(fontsize=7)
        fig.suptitle(f"{results['dataset']}: error against the largest rotation angle")
        fig.tight_layout()
        path = folder / f"{stem}_{name}.png"
        fig.savefig(path, dpi=110)
        written.append(str(path))
    return written


def write_report(results: dict, output_dir, stem: str | None = None) -> list[str]:
    """Write ``<stem>.json``, ``<stem>.md`` and PNG plots; return the paths."""
    folder = Path(output_dir)
    folder.mkdir(parents=True, exist_ok=True)
    stem = stem or results["dataset"]
    json_path = folder / f"{stem}.json"
    json_path.write_text(json.dumps(results, indent=1, default=float))
    md_path = folder / f"{stem}.md"
    md_path.write_text(markdown(results))
    return [str(json_path), str(md_path), *_plots(results, folder, stem)]
