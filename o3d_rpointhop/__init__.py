"""o3d-rpointhop: unsupervised, rotation-invariant R-PointHop point descriptors and
global-to-local registration for Open3D and scikit-learn.

The package is built in layers that import one way (docs/design.md): ``_utils`` (leaves)
<- the public tools (``transforms``, ``open3d_interop``, ``io``, ``datasets``,
``plotting``) <- ``descriptors`` <- ``registration`` <- ``batch``, ``evaluation``
(benchmarks) and ``cli``. This module only re-exports.
"""

from ._version import __version__
from .descriptors import FPFHTransformer, RPointHopTransformer
from .open3d_interop import to_open3d_feature, to_point_cloud
from .registration import (
    ConsensusGlobal,
    Correspondences,
    FGRGlobal,
    GeneralizedICP,
    MultiScaleICP,
    PointToPlaneICP,
    PointToPointICP,
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

__all__ = [
    "ConsensusGlobal",
    "Correspondences",
    "FGRGlobal",
    "FPFHTransformer",
    "GeneralizedICP",
    "MultiScaleICP",
    "PointToPlaneICP",
    "PointToPointICP",
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
