"""Progress bars on stderr (``tqdm``), shown only where someone can watch them."""

from __future__ import annotations

import sys

__all__ = ["progress_bar"]


def progress_bar(total: int, *, desc: str, unit: str, enabled: bool | None, large: bool = True):
    """A ``tqdm`` bar on stderr, or ``None`` for no bar.

    ``enabled``: ``True``/``False`` as asked; ``None``: a bar only for a ``large`` job,
    and only when stderr is a terminal (tqdm's own ``disable=None`` rule), so tests,
    pipes, log files and CI stay silent.
    """
    if enabled is False or (enabled is None and not large):
        return None
    from tqdm.auto import tqdm

    bar = tqdm(
        total=total,
        desc=desc,
        unit=unit,
        file=sys.stderr,
        leave=False,
        dynamic_ncols=True,
        disable=None if enabled is None else False,
    )
    if bar.disable:
        bar.close()
        return None
    return bar
