"""o3d-rpointhop: unsupervised, rotation-invariant R-PointHop point descriptors and
global-to-local registration for Open3D and scikit-learn."""

from ._version import __version__
from .correspondences import Correspondences, find_correspondences
from .fpfh import FPFHTransformer
from .open3d_interop import to_open3d_feature, to_point_cloud
from .registration import (
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
    register,
    register_multiway,
    registration_scorer,
)
from .rpointhop import RPointHopTransformer
from .transforms import rigid_transform

__all__ = [
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
    "find_correspondences",
    "register",
    "register_multiway",
    "registration_scorer",
    "rigid_transform",
    "to_open3d_feature",
    "to_point_cloud",
]
