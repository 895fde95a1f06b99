"""What a registration uses when not told: the descriptor, the global cloud size and the
global step."""

from __future__ import annotations

from typing import Any

from ..descriptors import RPointHopTransformer

__all__ = [
    "DEFAULT_MODEL",
    "DEFAULT_GLOBAL_METHOD",
    "DEFAULT_GLOBAL_POINTS",
    "FALLBACK_SUPPORT",
    "FPFH_FALLBACK",
    "SCENE_FPFH_WEIGHT",
    "TRUST_SUPPORT",
    "default_descriptor",
    "resolve_global_method",
    "resolve_global_points",
]

#: The shipped model ``register()`` describes with when given no descriptor: the one-hop
#: object model (96 neighbours, 24-D), chosen on ModelNet40 *training* shapes for
#: success and time together (``benchmarks/object_model_selection.py``, two folds of
#: the training subset, seed 7, success up to symmetry resampled / noisy / partial):
#: 100 / 99.3 / 79.2 % at 0.29x / 0.25x / 0.32x the time of Open3D's FPFH recipe,
#: against the paper's four-hop model's 100 / 98.6 / 71.5 % at 0.44x / 0.41x / 0.47x.
DEFAULT_MODEL = "object"

#: The least ``RegistrationResult.support`` (share of the global step's matches the
#: pose explains) of a result the command line trusts, chosen on every official pair
#: of the scene model's four training scenes (``benchmarks/support_threshold.py``:
#: the largest threshold keeping every right 3DMatch claim; 3DLoMatch claims right
#: 74.0 -> 83.3 %). Right object results sit above it too (training crops: 0.011 up).
TRUST_SUPPORT = 0.01

#: Size of the global step's clouds when neither the call nor the descriptor names one.
DEFAULT_GLOBAL_POINTS = 2048

#: The global step of ``register(global_method="auto")`` for a descriptor that states
#: none (``registration_global_method_``), chosen on pairs of ModelNet40 *training*
#: shapes (seed 7, success up to symmetry, RANSAC / consensus): the ModelNet40 model
#: resampled 99.3 / 97.2 %, resampled-partial 77.8 / 75.7 %, paper's partial 91.7 /
#: 94.4 %; FPFH 93.1 / 79.9 %, 70.8 / 62.5 %, 96.5 / 97.9 %. On scenes the consensus
#: wins (FPFH on the training scenes of 3DMatch: 77.0 / 26.3 % against 83.6 / 43.9 %),
#: so scene models state it and FPFH on scenes takes ``global_method="consensus"``.
DEFAULT_GLOBAL_METHOD = "ransac"

#: The share of its matches under which the model's estimate makes the FPFH fallback
#: ask FPFH's consensus too (``PooledMatcher(combine="fallback")``'s ``min_support``),
#: chosen by ``benchmarks/fallback_selection.py`` on every official pair of the four
#: training scenes (the most pairs registered, then the smallest share): 118 / 121
#: and 163 / 195 (3DMatch / 3DLoMatch) from 0.015 to 0.03, against 117 and 163 at 0.01,
#: FPFH asked on 16 + 90 pairs against 8 + 52.
FALLBACK_SUPPORT = 0.015

#: Whether ``register()``'s consensus, where a model states it (``global_method="auto"``),
#: asks FPFH too when the model's estimate explains under :data:`FALLBACK_SUPPORT` of its
#: matches (``PooledMatcher(combine="fallback")``: FPFH's consensus beside the model's,
#: every hypothesis verified together). Chosen on every official pair of the scene
#: model's four training scenes: with the sensors known
#: (``scene_fpfh_fallback_training.*``) 3DMatch 117 / 121 and 3DLoMatch 163 / 195
#: registered against the model alone's 114 and 156 (3 and 8 gained, 0 and 1 lost;
#: FPFH's consensus always asked: 117 and 163 at twice the time), at 1.04x / 1.05x the
#: model alone's median time; without them (``..._no_viewpoints.*``) 113 and 121 against
#: 111 and 99 (2 and 23 gained, 0 and 1 lost) at 1.09x / 1.44x (docs/low_overlap.md,
#: "FPFH as a fallback").
FPFH_FALLBACK = True

#: FPFH's weight beside R-PointHop in a :class:`~o3d_rpointhop.DescriptorUnion` (each
#: part's rows at unit length): chosen for the shipped scene model on every official
#: 3DMatch pair of its training scenes among 0.5, 0.7 and 1 (3DLoMatch 144, 148 and 145
#: of 195 registered, 3DMatch 112 of 121 at 0.7, as without FPFH; docs/registration.md).
SCENE_FPFH_WEIGHT = 0.7


def default_descriptor() -> RPointHopTransformer:
    """The descriptor ``register()``, the CLI and the benchmarks use when given none: the
    shipped :data:`DEFAULT_MODEL` (``pretrained("object")``)."""
    return RPointHopTransformer.pretrained(DEFAULT_MODEL)


def resolve_global_points(n_global_points: int | str, descriptor: Any = None) -> int:
    """The number of points the global step downsamples each cloud to.

    Parameters
    ----------
    n_global_points : int or "auto"
        An int (at least 3; checked by the public entry points) is used as given.
        ``"auto"``: the descriptor's ``registration_points_`` when it has one (a model
        states the cloud size it was made for: the shipped scene model says 4096, chosen
        on its training scenes), else :data:`DEFAULT_GLOBAL_POINTS`.
    descriptor : transformer or None

    Returns
    -------
    int
    """
    if n_global_points == "auto":
        hint = getattr(descriptor, "registration_points_", None)
        return DEFAULT_GLOBAL_POINTS if hint is None else int(hint)
    return int(n_global_points)


def resolve_global_method(global_method: Any, descriptor: Any = None) -> Any:
    """The global step ``register()`` runs for ``global_method``.

    Parameters
    ----------
    global_method : str, RegistrationStep or None
        Anything but ``"auto"`` is returned as given. ``"auto"``: the descriptor's
        ``registration_global_method_`` when it states one (the shipped scene model:
        ``"consensus"``, chosen on its training scenes), else
        :data:`DEFAULT_GLOBAL_METHOD`.
    descriptor : transformer or None
        ``None`` stands for :func:`default_descriptor`, which states no global step.

    Returns
    -------
    str, RegistrationStep or None
    """
    if not (isinstance(global_method, str) and global_method == "auto"):
        return global_method
    hint = getattr(descriptor, "registration_global_method_", None)
    return DEFAULT_GLOBAL_METHOD if hint is None else str(hint)
