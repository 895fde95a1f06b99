"""Stanford Bunny benchmark: real scan pairs with ``bun.conf`` poses, and the paper's
protocol."""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from ..descriptors import RPointHopTransformer
from ..registration.defaults import default_descriptor
from ._common import (
    Progress,
    evaluate_methods,
    machine_facts,
    model_facts,
    register_resolution,
)
from .methods import check_methods
from .metrics import overlap_share
from .provenance import run_provenance
from .records import as_rows

__all__ = ["BUNNY_PROTOCOLS", "OVERLAP_DISTANCE", "run_bunny"]

#: Two scans' points within this distance (about four point spacings of the Stanford
#: scans) count as the same surface: a scan's overlap with bun000 is the share of its
#: points that the true pose brings this close to bun000's.
OVERLAP_DISTANCE = 0.002

BUNNY_PROTOCOLS = {
    "scans": "real range scans registered to bun000, ground truth from bun.conf",
    "paper": "the paper's: each scan against a differently sampled copy of itself (2048 "
    "random points each), moved by Euler angles in [0, 45] deg and a translation in "
    "[-0.5, 0.5] m",
}


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

    ``"scans"``: every other scan registered to ``bun000`` (success: < 2 deg, < 2 mm),
    with each scan's overlap with ``bun000`` (:func:`~.metrics.overlap_share` at
    :data:`OVERLAP_DISTANCE`) under ``"overlap"``.
    ``"paper"``: each scan against a differently sampled copy of itself (2048 random
    points each) moved by Euler angles in [0, 45] deg and a translation in
    [-0.5, 0.5] m, as in the paper (success: < 5 deg, < 5 mm).
    """
    from scipy.spatial.transform import Rotation

    from ..datasets.bunny import BUNNY_SCANS, load_bunny
    from .protocols import Pair

    methods = check_methods(methods, "bunny")
    model = model if model is not None else default_descriptor()
    scans = load_bunny(BUNNY_SCANS, data)
    out = {
        "dataset": "bunny",
        "settings": {"seed": seed, **model_facts(model), **machine_facts()},
        "protocols": {},
    }
    out["provenance"] = run_provenance(methods, model)
    rng = np.random.default_rng(seed)

    for protocol in protocols:
        if protocol == "scans":
            target = scans["bun000"]
            pairs = [
                Pair(s.points, target.points, s.relative_pose(target), s.points, name)
                for name, s in scans.items()
                if name != "bun000"
            ]
            tol = (2.0, 0.002)
            overlap = {
                p.name: round(overlap_share(p.source, p.target, p.truth, OVERLAP_DISTANCE), 3)
                for p in pairs
            }
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
            overlap = None
        else:
            raise ValueError(f"unknown bunny protocol {protocol!r}; choose 'scans' or 'paper'")
        bar = Progress(len(methods) * len(pairs), f"bunny {protocol}", progress)
        summaries, records = evaluate_methods(
            pairs, methods, model, register_resolution, seed, bar, tol=tol
        )
        out["protocols"][protocol] = {
            "description": BUNNY_PROTOCOLS[protocol],
            "success": f"rotation error < {tol[0]} deg and translation error < {tol[1] * 1000} mm",
            "summary": summaries,
            "records": as_rows(records),
        }
        if overlap is not None:
            out["protocols"][protocol]["overlap"] = overlap
    return out
