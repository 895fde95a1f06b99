"""What the dataset runners share: progress, machine facts, resolutions, the method loop."""

from __future__ import annotations

import platform
from collections.abc import Callable
from pathlib import Path

from .._utils.progress import progress_bar
from ..descriptors import RPointHopTransformer
from ..open3d_interop import to_point_cloud
from ..registration.defaults import DEFAULT_GLOBAL_POINTS
from ..registration.settings import resolve_voxel_size
from .diagnostics import choice_diagnostics
from .metrics import is_symmetry, modified_chamfer, pair_errors, summarize
from .records import PairRecord
from .runner import run_method

__all__ = ["Progress", "evaluate_methods", "fixed_resolution", "register_resolution"]


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


def register_resolution(pair) -> float:
    """``register()``'s resolution rule (``voxel_size="auto"``, 2048 global points)
    applied to a pair as given: the bunny benchmark's Open3D recipes run at it, so that
    every method of a run works at about one resolution. (``register()`` applies the rule
    to centred clouds, which can shift the voxel grid and so the chosen voxel slightly;
    the 3DMatch benchmark takes the voxel from a ``RegistrationContext`` instead, which is
    exactly ``register()``'s. Kept as it is so that the bunny results stay comparable.)"""
    source, target = to_point_cloud(pair.source), to_point_cloud(pair.target)
    return resolve_voxel_size(source, target, "auto", DEFAULT_GLOBAL_POINTS)[0]


def fixed_resolution(voxel: float) -> Callable[[object], float]:
    """One resolution for every pair (ModelNet40: Open3D's tutorial value for objects
    in the unit sphere)."""
    return lambda pair: voxel


def peak_rss_mb() -> float:
    """This process's peak resident memory in MiB (Linux's VmHWM: ``ru_maxrss`` keeps the
    peak of the parent across fork/exec, so it cannot tell a child's own peak; elsewhere
    ``ru_maxrss`` is all there is)."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def machine_facts() -> dict:
    """The machine, the library versions and the thread budget (see
    :data:`~.runner.THREAD_BUDGETS`) a run was measured with."""
    import os

    from .._utils.provenance import library_versions
    from .runner import current_thread_budget

    versions = library_versions()
    return {
        "machine": f"{platform.machine()}, {len(os.sched_getaffinity(0))} cores",
        **{k: versions[k] for k in ("python", "open3d", "numpy", "o3d_rpointhop")},
        "thread_budget": current_thread_budget(),
    }


def model_facts(model: RPointHopTransformer) -> dict:
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


def evaluate_methods(pairs, methods, model, voxel_of, seed, progress, shapes=None, tol=(5.0, 0.05)):
    """Run every method on every pair; return ``{method: summary}`` and
    ``{method: [PairRecord, ...]}``.

    ``shapes`` (the whole shape of each pair) enables the symmetry check; ``tol`` is the
    success threshold (rotation in degrees, translation in the data's unit).
    """
    summaries, records = {}, {}
    voxels = [voxel_of(pair) for pair in pairs]  # once per pair, not once per method
    for method in methods:
        recs = []
        for k, pair in enumerate(pairs):
            run = run_method(
                method, pair.source, pair.target, descriptor=model, voxel=voxels[k], seed=seed
            )
            symmetric = None
            if shapes is not None:
                symmetric = is_symmetry(run.transformation, pair.truth, shapes[k])
            errors = pair_errors(run.transformation, pair.truth)
            chamfer = None
            if pair.shape is not None:
                chamfer = modified_chamfer(
                    run.transformation, pair.truth, pair.source, pair.target, pair.shape
                )
            recs.append(
                PairRecord(
                    **errors,
                    seconds=run.seconds,
                    pair=pair.name,
                    symmetric=symmetric,
                    chamfer=chamfer,
                    diagnostics=(
                        None if run.result is None else choice_diagnostics(run.result, pair.truth)
                    ),
                )
            )
            progress.step(method)
        summaries[method] = summarize(recs, *tol)
        records[method] = recs
    return summaries, records
