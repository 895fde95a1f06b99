"""o3d-rpointhop: unsupervised, rotation-invariant R-PointHop point descriptors and
global-to-local registration for Open3D and scikit-learn.

The package is built in layers that import one way (docs/design.md): ``_utils`` (leaves)
<- the public tools (``transforms``, ``open3d_interop``, ``io``, ``poses``,
``datasets``, ``plotting``) <- ``descriptors`` <- ``registration`` <- ``batch``,
``viewer``, ``evaluation`` (benchmarks) and ``cli``. This module only re-exports, and
lazily (as SciPy and scikit-image do): ``import o3d_rpointhop`` loads nothing heavy,
and each name loads its module on first use.
"""

from __future__ import annotations

import importlib
import logging
from typing import TYPE_CHECKING, Any

from ._version import __version__

# The library logs what it does under "o3d_rpointhop" (reading files, each registration
# step, multiway's pairs and edges); an application chooses where it goes.
logging.getLogger(__name__).addHandler(logging.NullHandler())

#: Every re-exported name and the module that defines it.
_EXPORTS = {
    "DescriptorUnion": "descriptors",
    "FPFHTransformer": "descriptors",
    "RPointHopTransformer": "descriptors",
    "to_open3d_feature": "open3d_interop",
    "to_point_cloud": "open3d_interop",
    "rigid_transform": "transforms",
    **dict.fromkeys(
        (
            "ConsensusGlobal",
            "Correspondences",
            "FGRGlobal",
            "GeneralizedICP",
            "Matcher",
            "MultiScaleICP",
            "PooledMatcher",
            "PointToPlaneICP",
            "PointToPointICP",
            "RANSACGlobal",
            "RegistrationPipeline",
            "RegistrationResult",
            "RegistrationSettings",
            "RegistrationStep",
            "RegistrationWarning",
            "SVDGlobal",
            "SymmetryCheck",
            "evaluate",
            "find_correspondences",
            "register",
            "register_multiway",
            "registration_scorer",
        ),
        "registration",
    ),
}

__all__ = [
    "ConsensusGlobal",
    "Correspondences",
    "DescriptorUnion",
    "FGRGlobal",
    "FPFHTransformer",
    "GeneralizedICP",
    "Matcher",
    "MultiScaleICP",
    "PointToPlaneICP",
    "PointToPointICP",
    "PooledMatcher",
    "RANSACGlobal",
    "RPointHopTransformer",
    "RegistrationPipeline",
    "RegistrationResult",
    "RegistrationSettings",
    "RegistrationStep",
    "RegistrationWarning",
    "SVDGlobal",
    "SymmetryCheck",
    "__version__",
    "evaluate",
    "find_correspondences",
    "register",
    "register_multiway",
    "registration_scorer",
    "rigid_transform",
    "to_open3d_feature",
    "to_point_cloud",
]


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        try:  # a submodule: o3d_rpointhop.viewer, o3d_rpointhop.poses, ...
            return importlib.import_module(f".{name}", __name__)
        except ModuleNotFoundError as exc:
            if exc.name != f"{__name__}.{name}":
                raise
            raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value  # later lookups skip __getattr__
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *_EXPORTS])


if TYPE_CHECKING:  # what type checkers and IDEs see
    from .descriptors import DescriptorUnion, FPFHTransformer, RPointHopTransformer
    from .open3d_interop import to_open3d_feature, to_point_cloud
    from .registration import (
        ConsensusGlobal,
        Correspondences,
        FGRGlobal,
        GeneralizedICP,
        Matcher,
        MultiScaleICP,
        PointToPlaneICP,
        PointToPointICP,
        PooledMatcher,
        RANSACGlobal,
        RegistrationPipeline,
        RegistrationResult,
        RegistrationSettings,
        RegistrationStep,
        RegistrationWarning,
        SVDGlobal,
        SymmetryCheck,
        evaluate,
        find_correspondences,
        register,
        register_multiway,
        registration_scorer,
    )
    from .transforms import rigid_transform
