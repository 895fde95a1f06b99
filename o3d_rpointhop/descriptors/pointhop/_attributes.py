"""Per-point attributes beside the coordinates, for the paper's scene variant.

R-PointHop's indoor variant (Sec. IV of the paper) describes a point not by its
neighbours' coordinates alone but also by their surface normals and covariance
eigenvalue features. Every attribute here is rigid-invariant by construction:

* ``"xyz"``: the neighbour's coordinates in the point's local reference frame (LRF),
  divided by the cloud's scale (the original R-PointHop input);
* ``"normal"``: the neighbour's normal, its own LRF's third axis (oriented by the LRF's
  sign rule, so no arbitrary flip), expressed in the point's LRF;
* ``"eigen"``: seven features of the neighbour's covariance eigenvalues
  ``l1 >= l2 >= l3`` normalised to sum 1 (``e_i``): linearity ``(e1 - e2) / e1``,
  planarity ``(e2 - e3) / e1``, scattering ``e3 / e1``, omnivariance
  ``(e1 e2 e3)^(1/3)``, anisotropy ``(e1 - e3) / e1``, eigenentropy ``-sum e_i ln e_i``
  and change of curvature ``e3``. All are scale-free and defined everywhere: on a wall
  (``e3 = 0``) ``0 ln 0`` is 0; a neighbourhood whose points all coincide gets zeros.

Hop 1 pools each attribute group into the eight octants of the point's LRF: 24 numbers
for ``"xyz"``, 24 for ``"normal"``, 56 for ``"eigen"``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["ATTRIBUTE_CHANNELS", "check_attributes", "eigen_features", "N_EIGEN_FEATURES"]

#: Channels each attribute group contributes per neighbour (8 octant means each).
ATTRIBUTE_CHANNELS = {"xyz": 3, "normal": 3, "eigen": 7}
N_EIGEN_FEATURES = ATTRIBUTE_CHANNELS["eigen"]


def check_attributes(value: Any) -> tuple[str, ...]:
    """``value`` as a tuple of attribute names: ``"xyz"`` first, no repeats.

    Raises
    ------
    ValueError
        For an unknown name, a repeated one, or a tuple without ``"xyz"``.
    """
    names = (value,) if isinstance(value, str) else value
    try:
        names = tuple(names)
    except TypeError:
        raise ValueError(f"attributes must be a sequence of names, got {value!r}") from None
    unknown = [n for n in names if n not in ATTRIBUTE_CHANNELS]
    if unknown or len(set(names)) != len(names) or not names or names[0] != "xyz":
        raise ValueError(
            f"attributes must start with 'xyz' and may add 'normal' and 'eigen', each once; "
            f"got {value!r}"
        )
    return names


def eigen_features(eigenvalues: np.ndarray) -> np.ndarray:
    """The seven eigenvalue features of every point.

    Parameters
    ----------
    eigenvalues : ndarray of shape (n, 3)
        Covariance eigenvalues, largest first, non-negative.

    Returns
    -------
    ndarray of shape (n, 7)
        Linearity, planarity, scattering, omnivariance, anisotropy, eigenentropy and
        change of curvature; finite for every input (zeros where all three are 0).
    """
    total = eigenvalues.sum(axis=1, keepdims=True)
    flat = total[:, 0] <= 0.0
    e = eigenvalues / np.where(total > 0.0, total, 1.0)
    e1 = np.where(flat, 1.0, e[:, 0])
    with np.errstate(divide="ignore", invalid="ignore"):
        log = np.where(e > 0.0, np.log(np.where(e > 0.0, e, 1.0)), 0.0)
    out = np.stack(
        [
            (e[:, 0] - e[:, 1]) / e1,
            (e[:, 1] - e[:, 2]) / e1,
            e[:, 2] / e1,
            np.cbrt(e[:, 0] * e[:, 1] * e[:, 2]),
            (e[:, 0] - e[:, 2]) / e1,
            -(e * log).sum(axis=1),
            e[:, 2],
        ],
        axis=1,
    )
    out[flat] = 0.0
    return out
