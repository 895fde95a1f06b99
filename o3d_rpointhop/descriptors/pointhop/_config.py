"""The hop parameters of R-PointHop, checked where one value depends on another."""

from __future__ import annotations

import numbers
from dataclasses import dataclass
from itertools import pairwise
from typing import Any

import numpy as np

from ._attributes import ATTRIBUTE_CHANNELS, check_attributes
from ._octants import N_OCTANTS

__all__ = ["HopConfig", "SAMPLING_METHODS"]

SAMPLING_METHODS = ("auto", "fps", "poisson")


def is_int(value: Any, low: int) -> bool:
    """An integer (not a bool) of at least ``low``."""
    return isinstance(value, numbers.Integral) and not isinstance(value, bool) and value >= low


def is_fraction(value: Any) -> bool:
    """A float (not an int) in (0, 1]."""
    return (
        isinstance(value, numbers.Real)
        and not isinstance(value, numbers.Integral)
        and 0.0 < value <= 1.0
    )


@dataclass(frozen=True)
class HopConfig:
    """Validated hop parameters of an :class:`~o3d_rpointhop.RPointHopTransformer`."""

    hop_sizes: tuple[float | int, ...]
    n_neighbors: tuple[int, ...]
    lrf_neighbors: int
    scale: str | float
    sampling: str = "auto"
    attributes: tuple[str, ...] = ("xyz",)
    pooling: str = "octants"

    @property
    def hop1_dim(self) -> int:
        """Length of the hop-1 input: eight octant means per attribute channel."""
        return N_OCTANTS * sum(ATTRIBUTE_CHANNELS[a] for a in self.attributes)

    @classmethod
    def from_params(
        cls,
        n_neighbors: Any,
        hop_sizes: Any,
        lrf_neighbors: int,
        scale: str | float,
        sampling: str = "auto",
        attributes: Any = ("xyz",),
        pooling: str = "octants",
    ) -> HopConfig:
        """The hop parameters, checked where a declarative constraint cannot say enough:
        the contents of the per-hop sequences (one hop size per neighbourhood size, all
        counts or all fractions, not increasing), attribute names and a finite scale.
        ``lrf_neighbors``, ``sampling``, ``pooling`` and the type of ``scale`` are taken as checked
        by the estimator's ``_parameter_constraints``. Raises ValueError naming the bad
        parameter."""
        try:
            n_neighbors = tuple(n_neighbors)
            sizes = tuple(hop_sizes)
        except TypeError:
            raise ValueError(
                f"n_neighbors and hop_sizes must be sequences, got {n_neighbors!r} and "
                f"{hop_sizes!r}"
            ) from None
        if not n_neighbors or not all(is_int(k, 1) for k in n_neighbors):
            raise ValueError(
                f"n_neighbors must be a non-empty sequence of ints >= 1, got {n_neighbors!r}"
            )
        if len(sizes) != len(n_neighbors):
            raise ValueError(
                f"hop_sizes has {len(sizes)} entries but n_neighbors has {len(n_neighbors)}; "
                "give one of each per hop"
            )
        if all(is_int(s, 1) for s in sizes):
            sizes = tuple(int(s) for s in sizes)
        elif all(is_fraction(s) for s in sizes):
            sizes = tuple(float(s) for s in sizes)
        else:
            raise ValueError(
                "hop_sizes must be all fractions in (0, 1] (floats) or all point counts >= 1 "
                f"(ints), got {hop_sizes!r}"
            )
        if any(b > a for a, b in pairwise(sizes)):
            raise ValueError(f"hop_sizes must not increase from hop to hop, got {hop_sizes!r}")
        if scale != "auto":
            if not np.isfinite(scale):
                raise ValueError(f"scale must be 'auto' or a positive number, got {scale!r}")
            scale = float(scale)
        return cls(
            hop_sizes=sizes,
            n_neighbors=tuple(int(k) for k in n_neighbors),
            lrf_neighbors=int(lrf_neighbors),
            scale=scale,
            sampling=sampling,
            attributes=check_attributes(attributes),
            pooling=pooling,
        )

    @property
    def n_hops(self) -> int:
        return len(self.n_neighbors)

    def sample_sizes(self, n_points: int) -> list[int]:
        """Number of points in ``S_1 .. S_H`` for a cloud of ``n_points``."""
        sizes = []
        for size in self.hop_sizes:
            if isinstance(size, (int, np.integer)):
                sizes.append(min(int(size), n_points))
            else:
                sizes.append(max(1, int(round(float(size) * n_points))))
        return sizes

    def shortfall(self, n_points: int) -> str | None:
        """Why a cloud of ``n_points`` is too small for these hops, or None if it is not."""
        if n_points < self.lrf_neighbors:
            return f"the local reference frame takes lrf_neighbors={self.lrf_neighbors} points"
        sizes = self.sample_sizes(n_points)
        sources = [n_points] + sizes[:-1]
        for h, (k, m) in enumerate(zip(self.n_neighbors, sources, strict=True), start=1):
            if m < k + 1:
                where = "the cloud" if h == 1 else f"the {m} points sampled for hop {h - 1}"
                return f"hop {h} takes n_neighbors[{h - 1}]={k} neighbours among {where}"
        return None

    def min_points(self) -> int:
        """Smallest cloud these hops accept."""
        n = max(self.lrf_neighbors, self.n_neighbors[0] + 1)
        while self.shortfall(n) is not None:
            n += 1
        return n
