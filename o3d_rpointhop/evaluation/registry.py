"""Every method every benchmark measures, in one registry of typed entries.

The registration benchmarks (``modelnet40``, ``bunny``, ``3dmatch``) run the pair
methods of :data:`~.methods.METHODS` (each a :class:`~.methods.Method` with its
runner); the scan-set benchmark (``multiway``) and the descriptor scaling script
(``benchmarks/scaling.py``) run the entries declared here. :func:`entries` lists them
all the same way, so that the command line, the scripts and the reports name a method
with one spelling and describe it with one sentence.
"""

from __future__ import annotations

from dataclasses import dataclass

from .methods import DATASETS, METHODS

__all__ = ["BENCHMARKS", "Entry", "entries"]


@dataclass(frozen=True)
class Entry:
    """One method of one benchmark.

    Attributes
    ----------
    benchmark : str
        One of :data:`BENCHMARKS`.
    name, description : str
    default : bool
        Run when no method is named.
    """

    benchmark: str
    name: str
    description: str
    default: bool = True


#: The scan-set benchmark's methods (``o3d-rpointhop benchmark multiway``).
MULTIWAY = (
    Entry(
        "multiway", "rpointhop", "R-PointHop (register()'s default model) through register_multiway"
    ),
    Entry("multiway", "fpfh", "FPFH (radii from the spacing) through the same pipeline"),
    Entry(
        "multiway",
        "open3d-recipe",
        "Open3D's multiway tutorial: FPFH + RANSAC + ICP per pair, its pose graph",
    ),
)
#: The descriptor scaling script's methods (``benchmarks/scaling.py``).
SCALING = (
    Entry("scaling", "rpointhop-object", "R-PointHop, the one-hop object model (24-D)"),
    Entry("scaling", "rpointhop-128", "R-PointHop, pretrained, 128 principal axes"),
    Entry("scaling", "rpointhop-32", "R-PointHop, pretrained, 32 principal axes"),
    Entry("scaling", "rpointhop-full", "R-PointHop, pretrained, 1624-D"),
    Entry(
        "scaling",
        "fpfh",
        "Open3D FPFH, normals 6x / histograms 15x the spacing, 30 / 100 neighbours",
    ),
)
#: Every benchmark the registry knows.
BENCHMARKS = (*DATASETS, "multiway", "scaling")


def entries(benchmark: str) -> dict[str, Entry]:
    """The methods of ``benchmark`` by name, in the order reports list them.

    Raises
    ------
    ValueError
        For a benchmark not in :data:`BENCHMARKS`.
    """
    if benchmark == "multiway":
        return {e.name: e for e in MULTIWAY}
    if benchmark == "scaling":
        return {e.name: e for e in SCALING}
    if benchmark not in DATASETS:
        raise ValueError(f"unknown benchmark {benchmark!r}; choose from {list(BENCHMARKS)}")
    return {
        m.name: Entry(benchmark, m.name, m.description, benchmark in m.default_on)
        for m in METHODS.values()
        if benchmark in m.datasets
    }
