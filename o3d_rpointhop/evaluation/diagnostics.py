"""Why a descriptor registers a pair or not: how many of its matches are right, and how
well its local frames repeat between the two clouds.

Measured on the clouds a registration describes (a
:class:`~o3d_rpointhop.registration.context.RegistrationContext`'s global clouds, in its
centred frame) against the pair's true transformation:

* **matches**: the mutual nearest-descriptor matches (feature-match recall's) and every
  match both ways (what :class:`~o3d_rpointhop.ConsensusGlobal` sees), each counted
  correct when its two points lie within ``radius`` of each other under the truth;
* **frame repeatability** (R-PointHop only): at true correspondences (a source point
  and the target point nearest to it under the truth, within one resolution), the share
  whose whole local frames agree within ``max_angle`` once the source frame is turned
  by the truth, and the shares whose normal axes agree with their sign (what
  viewpoints fix) and without it (what the geometry fixes).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from ..transforms import apply_transform

__all__ = [
    "FRAME_ANGLE_DEG",
    "choice_diagnostics",
    "frame_repeatability",
    "match_inliers",
    "pair_diagnostics",
    "true_correspondences",
]

#: Two frames (or axes) "agree" within this angle.
FRAME_ANGLE_DEG = 25.0


def true_correspondences(
    source: np.ndarray, target: np.ndarray, truth: np.ndarray, radius: float
) -> np.ndarray:
    """Pairs ``(i, j)``: source point ``i`` moved by ``truth`` and its nearest target
    point ``j``, where they lie within ``radius``."""
    distance, nearest = cKDTree(target).query(apply_transform(source, truth))
    inside = np.flatnonzero(distance <= radius)
    return np.c_[inside, nearest[inside]].astype(np.int64)


def frame_repeatability(
    source_frames: np.ndarray,
    target_frames: np.ndarray,
    pairs: np.ndarray,
    rotation: np.ndarray,
    max_angle: float = FRAME_ANGLE_DEG,
) -> dict:
    """How often the frames at true correspondences agree.

    Parameters
    ----------
    source_frames, target_frames : ndarray of shape (n, 3, 3)
        ``frames[i, :, j]`` is axis ``j`` of point ``i``; axis 2 is the normal.
    pairs : ndarray of shape (p, 2)
        True correspondences (:func:`true_correspondences`).
    rotation : ndarray of shape (3, 3)
        The true rotation from source to target.
    max_angle : float, default=25.0
        Degrees.

    Returns
    -------
    dict
        ``frames``: share whose whole frames agree (the rotation between them is below
        ``max_angle``); ``normals``: share whose normal axes agree, sign included;
        ``normal_lines``: share whose normal axes agree up to sign; ``correspondences``:
        how many were compared. Shares are None without correspondences.
    """
    count = len(pairs)
    if count == 0:
        return {"frames": None, "normals": None, "normal_lines": None, "correspondences": 0}
    turned = rotation @ source_frames[pairs[:, 0]]  # (p, 3, 3)
    target = target_frames[pairs[:, 1]]
    # The angle of the rotation between two frames: trace(A^T B) = 1 + 2 cos(angle).
    trace = np.einsum("pij,pij->p", turned, target)
    cos_limit = np.cos(np.radians(max_angle))
    frames = (trace - 1.0) / 2.0 >= cos_limit
    normal_cos = np.einsum("pi,pi->p", turned[:, :, 2], target[:, :, 2])
    return {
        "frames": float(frames.mean()),
        "normals": float((normal_cos >= cos_limit).mean()),
        "normal_lines": float((np.abs(normal_cos) >= cos_limit).mean()),
        "correspondences": int(count),
    }


def match_inliers(context, descriptor, truth: np.ndarray, radius: float = 0.1) -> tuple:
    """The share and the number of the mutual nearest-descriptor matches between the
    global clouds of a :class:`~o3d_rpointhop.registration.context.RegistrationContext`
    that lie within ``radius`` of each other under ``truth`` (feature-match recall counts
    a pair when the share exceeds 0.05)."""
    from ..registration.correspondences import find_correspondences

    src, tgt = (np.asarray(c.points) for c in context.clouds("global"))
    corr = find_correspondences(
        context.features(descriptor, "source"),
        context.features(descriptor, "target"),
        mutual_filter=True,
    )
    moved = apply_transform(src[corr.pairs[:, 0]], context.to_local(truth))
    inside = np.linalg.norm(moved - tgt[corr.pairs[:, 1]], axis=1) < radius
    return float(inside.mean()), int(inside.sum())


def _correct_both_ways(context, descriptor, truth: np.ndarray, radius: float) -> tuple:
    """Every nearest-descriptor match, source to target and back (duplicates once), and
    how many are within ``radius`` under ``truth``: ``(matches, correct)``."""
    from ..registration.correspondences import find_correspondences

    src, tgt = (np.asarray(c.points) for c in context.clouds("global"))
    f_src, f_tgt = context.features(descriptor, "source"), context.features(descriptor, "target")
    there = find_correspondences(f_src, f_tgt).pairs
    back = find_correspondences(f_tgt, f_src).pairs[:, ::-1]
    pairs = np.unique(np.concatenate([there, back]), axis=0)
    moved = apply_transform(src[pairs[:, 0]], context.to_local(truth))
    correct = np.linalg.norm(moved - tgt[pairs[:, 1]], axis=1) < radius
    return len(pairs), int(correct.sum())


def pair_diagnostics(context, descriptor: Any, truth: np.ndarray, radius: float = 0.1) -> dict:
    """The diagnostics of one pair for one descriptor (see the module's docstring).

    Parameters
    ----------
    context : RegistrationContext
        The pair as a registration prepares it (its resolution, global clouds and
        viewpoints).
    descriptor : transformer
        R-PointHop (frames measured) or any other descriptor (matches only).
    truth : ndarray of shape (4, 4)
        Source to target, in the caller's coordinates.
    radius : float, default=0.1
        When a match is correct (3DMatch's 0.1 m).

    Returns
    -------
    dict
        ``inlier_ratio`` and ``inlier_count`` of the mutual matches; ``matches`` and
        ``correct_matches`` both ways; ``frames``, ``normals``, ``normal_lines`` and
        ``correspondences`` (:func:`frame_repeatability`), None for a descriptor
        without local frames.
    """
    ratio, count = match_inliers(context, descriptor, truth, radius)
    matches, correct = _correct_both_ways(context, descriptor, truth, radius)
    out = {
        "inlier_ratio": ratio,
        "inlier_count": count,
        "matches": matches,
        "correct_matches": correct,
    }
    frames_of = getattr(descriptor, "local_frames", None)
    if frames_of is None:
        return {**out, "frames": None, "normals": None, "normal_lines": None}
    local = context.to_local(truth)
    clouds = dict(zip(("source", "target"), context.clouds("global"), strict=True))
    frames = {}
    for which, cloud in clouds.items():
        view = None if context.viewpoints is None else context.viewpoints[which]
        frames[which] = frames_of(np.asarray(cloud.points), viewpoints=view)
    pairs = true_correspondences(
        np.asarray(clouds["source"].points),
        np.asarray(clouds["target"].points),
        local,
        context.voxel_size,
    )
    repeat = frame_repeatability(frames["source"], frames["target"], pairs, local[:3, :3])
    return {**out, **repeat}


def choice_diagnostics(result: Any, truth: np.ndarray) -> dict | None:
    """Why a registration went as it did, from its global step: how many matches it
    worked on, the share the truth explains (within the step's own inlier distance:
    few right matches mean the matches failed) and the share its estimate explains
    (``support``, :attr:`~o3d_rpointhop.RegistrationResult.support`), and, when it
    verified several hypotheses, their scores, which one it chose and its margin (right
    matches but a wrong pose mean the choice failed), and whether a fallback part was
    asked (``PooledMatcher(combine="fallback")``). None for a result without a
    global step.

    Parameters
    ----------
    result : RegistrationResult
    truth : ndarray of shape (4, 4)
        The source-to-target truth in the frames the result was computed in.
    """
    for step in result.steps:
        if step.matches is None:
            continue
        source, target = step.matches[:, 0], step.matches[:, 1]
        distance = step.info["max_correspondence_distance"]
        moved = apply_transform(source, truth)
        right = np.linalg.norm(moved - target, axis=1) < distance
        out = {
            "matches": int(len(right)),
            "match_inlier_ratio": float(right.mean()),
            "support": result.support,
        }
        for key in ("hypothesis_scores", "chosen_hypothesis", "margin", "fallback"):
            if key in step.info:
                out[key] = step.info[key]
        return out
    return None
