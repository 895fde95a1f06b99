"""The flags that decide what a screened pair needs to become an edge of the pose graph
(``reconstruct``'s ``--min-fitness`` and ``--max-violation``)."""

from __future__ import annotations

import argparse

__all__ = ["add_edge_limits"]


def _share_or_none(text: str) -> float | str:
    """``--max-violation``: a share in [0, 1], or ``none``."""
    if text == "none":
        return text
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f"expected a share in [0, 1] or 'none', got {text!r}")
    return value


def add_edge_limits(parser: argparse.ArgumentParser) -> None:
    """``--min-fitness`` and ``--max-violation``: what a screened pair needs to become
    an edge of the pose graph."""
    parser.add_argument(
        "--min-fitness",
        type=float,
        help="share of a scan within 1.5 resolutions of the other for a pair to become an "
        "edge (default 0.3; [multiway] min_fitness)",
    )
    parser.add_argument(
        "--max-violation",
        type=_share_or_none,
        help="with the sensors known, the largest share of either scan a pair's pose may put "
        "in space the other sensor saw empty, for the pair to become an edge, or 'none' "
        "(default 0.1; [multiway] max_violation)",
    )
