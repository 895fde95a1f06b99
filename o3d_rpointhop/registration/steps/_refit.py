"""The refit loop the global estimators finish with: fit again on the inliers while that
gathers more of them."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

__all__ = ["refit_while_growing"]


def refit_while_growing(
    transformation: np.ndarray,
    within: Callable[[np.ndarray], np.ndarray],
    fit: Callable[[np.ndarray, np.ndarray], np.ndarray],
    rounds: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Refit ``transformation`` on its inliers for at most ``rounds`` rounds.

    Parameters
    ----------
    transformation : ndarray of shape (4, 4)
        The estimate to start from.
    within : callable
        ``within(transformation) -> bool mask`` of the inliers under a transformation.
    fit : callable
        ``fit(transformation, inliers) -> (4, 4)``: the refit on those inliers; a
        ``ValueError`` (collinear inliers) ends the loop with what there is.
    rounds : int

    Returns
    -------
    transformation, inliers
        The last refit that lost no inlier, and its inliers. The loop stops early when
        fewer than 3 inliers remain, when a refit loses inliers (it is not taken) or
        when it gains none (it is taken).
    """
    inliers = within(transformation)
    for _ in range(rounds):
        if inliers.sum() < 3:
            break
        try:
            refit = fit(transformation, inliers)
        except ValueError:
            break
        more = within(refit)
        if more.sum() < inliers.sum():
            break
        grew = more.sum() > inliers.sum()
        transformation, inliers = refit, more
        if not grew:
            break
    return transformation, inliers
