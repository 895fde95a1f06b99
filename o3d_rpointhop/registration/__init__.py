"""Registration: global estimates from descriptors, then ICP refinement chains."""

from .context import RegistrationContext, RegistrationWarning
from .multiway import MultiwayResult, register_multiway
from .pipeline import RegistrationPipeline, RegistrationResult, register
from .steps import (
    FGRGlobal,
    GeneralizedICP,
    MultiScaleICP,
    PointToPlaneICP,
    PointToPointICP,
    RANSACGlobal,
    RegistrationStep,
    StepResult,
    SVDGlobal,
)
from .symmetry import SymmetryCheck

__all__ = [
    "FGRGlobal",
    "GeneralizedICP",
    "MultiScaleICP",
    "PointToPlaneICP",
    "PointToPointICP",
    "RANSACGlobal",
    "RegistrationContext",
    "RegistrationPipeline",
    "RegistrationResult",
    "RegistrationStep",
    "RegistrationWarning",
    "SVDGlobal",
    "StepResult",
    "SymmetryCheck",
    "MultiwayResult",
    "register",
    "register_multiway",
]
