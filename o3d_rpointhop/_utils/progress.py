"""Progress bars on stderr (``tqdm``), shown only where someone can watch them."""

from __future__ import annotations

import sys

__all__ = ["progress_bar", "wants_progress"]


def wants_progress(enabled: bool | None, large: bool = True) -> bool:
    """``True``/``False`` as asked; ``None``: only for a large job with stderr a terminal
    (so tests, pipes, log files and CI stay silent)."""
    if enabled is not None:
        return bool(enabled)
    isatty = getattr(sys.stderr, "isatty", None)
    return bool(large and isatty is not None and isatty())


def progress_bar(total: int, *, desc: str, unit: str, enabled: bool | None, large: bool = True):
    """A ``tqdm`` bar on stderr, or ``None`` when :func:`wants_progress` says no."""
    if not wants_progress(enabled, large):
        return None
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=desc, unit=unit, file=sys.stderr, leave=False, dynamic_ncols=True)
