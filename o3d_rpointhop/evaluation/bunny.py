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

__all__ = ["BUNNY_PROTOCOLS", "DRAGON_TARGET", "OVERLAP_DISTANCE", "default_protocols", "run_bunny"]

#: Two scans' points within this distance (about four point spacings of the Stanford
#: scans) count as the same surface: a scan's overlap with bun000 is the share of its
#: points that the true pose brings this close to bun000's.
OVERLAP_DISTANCE = 0.002

BUNNY_PROTOCOLS = {
    "scans": "real range scans registered to bun000, ground truth from bun.conf",
    "paper": "the paper's: each scan against a differently sampled copy of itself (2048 "
    "random points each), moved by Euler angles in [0, 45] deg and a translation in "
    "[-0.5, 0.5] m",
    "dragon": "the Stanford dragon's real range scans registered to dragonStandRight_0, "
    "ground truth from dragonStandRight.conf",
}

#: The dragon scan the others are registered to (the first of the stand's turntable).
DRAGON_TARGET = "dragonStandRight_0"


def default_protocols(data=None) -> list[str]:
    """The protocols run when none is named: the bunny's two, and the dragon's when two
    of its scans or more are in the data folder (listed, not read)."""
    from ..datasets.bunny import dragon_files

    try:
        _, found = dragon_files(data)
    except FileNotFoundError:
        return ["scans", "paper"]
    return ["scans", "paper", "dragon"] if len(found) >= 2 else ["scans", "paper"]


def run_bunny(
    protocols: Iterable[str],
    methods: Iterable[str],
    *,
    data=None,
    seed: int = 0,
    model: RPointHopTransformer | None = None,
    progress: bool = True,
) -> dict:
    """Stanford Bunny: real scan pairs with ``bun.conf`` poses, and the paper's protocol;
    the Stanford dragon's real scan pairs.

    ``"scans"``: every other scan registered to ``bun000`` (success: < 2 deg, < 2 mm),
    with each scan's overlap with ``bun000`` (:func:`~.metrics.overlap_share` at
    :data:`OVERLAP_DISTANCE`) under ``"overlap"``.
    ``"dragon"``: the same for the dragon's "stand" scans present in the data folder
    (:func:`~o3d_rpointhop.datasets.bunny.load_dragon`), every other one registered to
    :data:`DRAGON_TARGET` with the ``dragonStandRight.conf`` poses as ground truth.
    ``"paper"``: each scan against a differently sampled copy of itself (2048 random
    points each) moved by Euler angles in [0, 45] deg and a translation in
    [-0.5, 0.5] m, as in the paper (success: < 5 deg, < 5 mm).
    """
    from scipy.spatial.transform import Rotation

    from ..datasets.bunny import BUNNY_SCANS, load_bunny, load_dragon
    from .protocols import Pair

    methods = check_methods(methods, "bunny")
    model = model if model is not None else default_descriptor()
    protocols = list(protocols)
    unknown = [p for p in protocols if p not in BUNNY_PROTOCOLS]
    if unknown:
        raise ValueError(
            f"unknown bunny protocol {unknown[0]!r}; choose from {list(BUNNY_PROTOCOLS)}"
        )
    scans = load_bunny(BUNNY_SCANS, data) if {"scans", "paper"} & set(protocols) else {}
    dragon = load_dragon(data) if "dragon" in protocols else {}
    out = {
        "dataset": "bunny",
        "settings": {"seed": seed, **model_facts(model), **machine_facts()},
        "protocols": {},
    }
    out["provenance"] = run_provenance(methods, model)
    rng = np.random.default_rng(seed)

    for protocol in protocols:
        if protocol in ("scans", "dragon"):
            found, first = (scans, "bun000") if protocol == "scans" else (dragon, DRAGON_TARGET)
            if first not in found:
                raise FileNotFoundError(f"{protocol}: no scan {first} in the data folder")
            target = found[first]
            pairs = [
                Pair(s.points, target.points, s.relative_pose(target), s.points, name)
                for name, s in found.items()
                if name != first
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
        else:  # checked above
            raise AssertionError(protocol)
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
