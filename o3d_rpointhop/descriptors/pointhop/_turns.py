"""A point's descriptor with its frame turned about the normal by quarter turns.

On walls, floors and table tops a local frame's normal axis repeats between two scans
but its in-plane axes often do not: the two largest covariance eigenvalues are nearly
equal, and the first axis's sign follows a skew that sampling decides. At true
correspondences of 3DMatch training pairs the in-plane axes agree up to a quarter turn
about three times as often as exactly. Describing a point under its frame turned by
``k`` quarter turns, and matching each point against every turn of the other cloud's
points, lets such correspondences match.

A quarter turn (``x' = y``, ``y' = -x``) moves the neighbours of octant
``(bx, by, bz)`` (bit 2 the first axis's side, bit 1 the second's, bit 0 the normal's)
to octant ``(by, 1 - bx, bz)``, and turns every in-plane vector the same way; nothing
else changes. So the turned descriptor is the same hops with their octants relabelled
and, at hop 1, the in-plane components of the coordinates and normals turned; no
neighbour search or frame is recomputed. A neighbour exactly on a frame plane moves with
its octant, where describing under a turned frame would keep it on the plane's positive
side (:mod:`._octants`).
"""

from __future__ import annotations

import numpy as np

from ._attributes import ATTRIBUTE_CHANNELS
from ._octants import N_OCTANTS

__all__ = ["N_TURNS_ALLOWED", "octant_turn", "turn_hop1"]

#: Turn counts a descriptor may be asked for: none, half turns, quarter turns.
N_TURNS_ALLOWED = (1, 2, 4)
#: Attribute groups whose channels are a vector in the frame (its first two components
#: turn with it); the other groups are invariant scalars.
_VECTOR_GROUPS = ("xyz", "normal")


def octant_turn(quarters: int) -> np.ndarray:
    """Where each octant's contents go under ``quarters`` quarter turns: ``(8,)`` uint8,
    ``new = table[old]``."""
    table = np.arange(N_OCTANTS, dtype=np.uint8)
    for _ in range(quarters % 4):
        bx, by, bz = (table >> 2) & 1, (table >> 1) & 1, table & 1
        table = (4 * by + 2 * (1 - bx) + bz).astype(np.uint8)
    return table


def turn_hop1(attributes: np.ndarray, names: tuple[str, ...], quarters: int) -> np.ndarray:
    """Hop-1 octant means ``(n, hop1_dim)`` (groups in ``names`` order, each octant-major)
    as they are under the frames turned by ``quarters`` quarter turns; a new array."""
    quarters %= 4
    if quarters == 0:
        return attributes.copy()
    table = octant_turn(quarters)
    n = len(attributes)
    out = np.empty_like(attributes)
    offset = 0
    for name in names:
        c = ATTRIBUTE_CHANNELS[name]
        width = N_OCTANTS * c
        block = attributes[:, offset : offset + width].reshape(n, N_OCTANTS, c)
        turned = np.empty_like(block)
        turned[:, table] = block
        if name in _VECTOR_GROUPS:
            x, y = turned[:, :, 0].copy(), turned[:, :, 1].copy()
            # quarters of (x, y) -> (y, -x): 1 -> (y, -x), 2 -> (-x, -y), 3 -> (-y, x)
            cos, sin = ((1, 0), (0, 1), (-1, 0), (0, -1))[quarters]
            turned[:, :, 0] = cos * x + sin * y
            turned[:, :, 1] = cos * y - sin * x
        out[:, offset : offset + width] = turned.reshape(n, width)
        offset += width
    return out
