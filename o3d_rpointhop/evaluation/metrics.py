"""Registration error measures: the paper's Euler-angle errors, isotropic errors, success,
3DMatch's official registration error, and McNemar's test between two methods."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..transforms import apply_transform, euler_angles_deg, rotation_error_deg, translation_error
from .records import PairRecord

__all__ = [
    "REGISTERED_RMSE",
    "is_symmetry",
    "mcnemar",
    "modified_chamfer",
    "overlap_share",
    "pair_errors",
    "rmse_3dmatch",
    "summarize",
]


#: The official 3DMatch test: a pair is registered when :func:`rmse_3dmatch` is under
#: this (metres).
REGISTERED_RMSE = 0.2


def _wrap(deg: np.ndarray) -> np.ndarray:
    return (deg + 180.0) % 360.0 - 180.0


def is_symmetry(estimate: np.ndarray, truth: np.ndarray, shape: np.ndarray) -> bool:
    """Whether ``estimate`` differs from ``truth`` only by a symmetry of ``shape``.

    ``S = estimate @ inv(truth)`` maps the target frame onto itself; it is a symmetry if
    it carries the whole shape onto its own surface: the mean distance from the moved
    points to the shape is at most the spacing between two independent samples of the
    surface (the shape's two halves). A vase turned about its axis, or a box turned by
    180 degrees, aligns perfectly at the "wrong" pose; no method can tell those apart.
    """
    motion = estimate @ np.linalg.inv(truth)
    half = len(shape) // 2
    tree = cKDTree(shape)
    reference = cKDTree(shape[:half]).query(shape[half:])[0].mean()
    moved = tree.query(apply_transform(shape, motion))[0].mean()
    return bool(moved <= reference)


def pair_errors(estimate: np.ndarray, truth: np.ndarray) -> dict:
    """Errors of one estimate: isotropic rotation/translation, and per-Euler-angle."""
    euler = _wrap(euler_angles_deg(estimate) - euler_angles_deg(truth))
    return {
        "rotation_error_deg": rotation_error_deg(estimate, truth),
        "translation_error": translation_error(estimate, truth),
        "euler_error_deg": euler.tolist(),
        "translation_error_xyz": (estimate[:3, 3] - truth[:3, 3]).tolist(),
    }


def modified_chamfer(
    estimate: np.ndarray,
    truth: np.ndarray,
    source: np.ndarray,
    target: np.ndarray,
    shape: np.ndarray,
) -> float:
    """RPM-Net's modified Chamfer distance of an estimate (Yew and Lee, CVPR 2020).

    The mean squared distance from the source moved by ``estimate`` to the whole clean
    shape (in the target frame), plus the mean squared distance from the target to the
    whole clean shape carried by the estimate's error (``estimate @ inv(truth)``): zero
    for the true motion up to noise, and measured against the clean whole shape so that
    neither crop penalises the other's missing part.
    """
    from scipy.spatial import cKDTree

    from ..transforms import apply_transform

    error = np.asarray(estimate) @ np.linalg.inv(np.asarray(truth))
    to_shape, _ = cKDTree(shape).query(apply_transform(source, estimate))
    to_target, _ = cKDTree(apply_transform(shape, error)).query(target)
    return float(np.mean(to_shape**2) + np.mean(to_target**2))


def overlap_share(
    source: np.ndarray, target: np.ndarray, truth: np.ndarray, distance: float
) -> float:
    """The share of ``source``'s points that the true motion ``truth`` brings within
    ``distance`` of a ``target`` point: how much of the source's surface the target
    also saw (the Stanford scans' overlap with bun000, at 2 mm)."""
    moved = apply_transform(np.asarray(source, dtype=np.float64), truth)
    dist, _ = cKDTree(np.asarray(target, dtype=np.float64)).query(
        moved, distance_upper_bound=distance
    )
    return float(np.mean(dist < distance))


def summarize(
    records: list[PairRecord], rotation_tol: float = 5.0, translation_tol: float = 0.05
) -> dict:
    """Aggregate per-pair records into the paper's and the isotropic measures.

    The paper's MSE, RMSE and MAE are over the three Euler angles (degrees) and the three
    translation components, as in DCP and R-PointHop. The measures up to symmetry are
    given when every record says whether its estimate is a symmetry of the shape.
    """
    euler = np.array([r.euler_error_deg for r in records])
    trans = np.array([r.translation_error_xyz for r in records])
    rot_iso = np.array([r.rotation_error_deg for r in records])
    trans_iso = np.array([r.translation_error for r in records])
    success = (rot_iso < rotation_tol) & (trans_iso < translation_tol)
    out = {
        "pairs": len(records),
        "mse_r": float(np.mean(euler**2)),
        "rmse_r": float(np.sqrt(np.mean(euler**2))),
        "mae_r": float(np.mean(np.abs(euler))),
        "mse_t": float(np.mean(trans**2)),
        "rmse_t": float(np.sqrt(np.mean(trans**2))),
        "mae_t": float(np.mean(np.abs(trans))),
        "median_rotation_error_deg": float(np.median(rot_iso)),
        "median_translation_error": float(np.median(trans_iso)),
        "success_rate": float(success.mean()),
        "seconds_per_pair": float(np.mean([r.seconds for r in records])),
    }
    if all(r.chamfer is not None for r in records):
        # RPM-Net's summary: isotropic errors as means, and the modified Chamfer distance.
        out["mean_rotation_error_deg"] = float(np.mean(rot_iso))
        out["mean_translation_error"] = float(np.mean(trans_iso))
        out["chamfer"] = float(np.mean([r.chamfer for r in records]))
    if all(r.symmetric is not None for r in records):
        sym = np.array([r.symmetric for r in records])
        out["success_rate_up_to_symmetry"] = float((success | sym).mean())
        # A failure that is a symmetry of the shape (a box turned by 180 deg) is an
        # ambiguity of the data, not an error of the method: the paper's MAE over the rest.
        kept = ~(sym & ~success)
        out["mae_r_not_symmetric"] = float(np.mean(np.abs(euler[kept]))) if kept.any() else 0.0
    return out


def rmse_3dmatch(estimate: np.ndarray, truth: np.ndarray, information: np.ndarray) -> float:
    """The official 3DMatch registration error: sqrt(xi^T I xi / I[0, 0]), with xi the
    translation and quaternion vector part of ``inv(truth) @ estimate`` and ``I`` the
    pair's ``gt.info`` matrix (a pair counts as registered below
    :data:`REGISTERED_RMSE`, 0.2 m)."""
    from scipy.spatial.transform import Rotation

    delta = np.linalg.inv(truth) @ estimate
    quat = Rotation.from_matrix(delta[:3, :3]).as_quat()  # x, y, z, w
    if quat[3] < 0:
        quat = -quat
    xi = np.r_[delta[:3, 3], quat[:3]]
    return float(np.sqrt(max(xi @ information @ xi / information[0, 0], 0.0)))


def mcnemar(a: np.ndarray, b: np.ndarray) -> dict:
    """McNemar's exact test of two methods' successes on the same pairs.

    Only the discordant pairs count: ``a_only`` where the first succeeded and the second
    failed, ``b_only`` the reverse. Under "the two methods are as good", each discordant
    pair goes either way with probability 1/2, so the two-sided p-value is the binomial
    tail of the smaller count; a small p-value (say below 0.05) says the difference in
    recall is not chance.
    """
    from scipy.stats import binomtest

    a, b = np.asarray(a, dtype=bool), np.asarray(b, dtype=bool)
    a_only, b_only = int((a & ~b).sum()), int((b & ~a).sum())
    n = a_only + b_only
    p = 1.0 if n == 0 else float(binomtest(min(a_only, b_only), n, 0.5).pvalue)
    return {"a_only": a_only, "b_only": b_only, "p_value": p}
