"""What a registration uses when not told: the descriptor and the global cloud size."""

from __future__ import annotations

from typing import Any

from ..descriptors import RPointHopTransformer

__all__ = [
    "DEFAULT_GLOBAL_POINTS",
    "REGISTRATION_COMPONENTS",
    "default_descriptor",
    "resolve_global_points",
]

#: Principal axes of the descriptor that registration uses by default, chosen on pairs
#: of ModelNet40 *training* shapes (seed 7; success of register() with 64 / 128 axes /
#: the full 1624-D descriptor): resampled 66.7 / 68.8 / 60.4 %, paper-partial 83.3 /
#: 87.5 / 89.6 %, resampled-partial 43.8 / 45.8 / 45.8 %. 128 axes also make matching
#: and RANSAC several times cheaper than 1624.
REGISTRATION_COMPONENTS = 128

#: Size of the global step's clouds when neither the call nor the descriptor names one.
DEFAULT_GLOBAL_POINTS = 2048


def default_descriptor() -> RPointHopTransformer:
    """The descriptor ``register()``, the CLI and the benchmarks use when given none: the
    pretrained ModelNet40 model projected on :data:`REGISTRATION_COMPONENTS` axes."""
    return RPointHopTransformer.pretrained(n_components=REGISTRATION_COMPONENTS)


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
