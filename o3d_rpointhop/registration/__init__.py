"""Registration: global estimates from descriptors, then ICP refinement chains.

Modules, one concept each: :mod:`.settings` (the resolution and every distance derived
from it), :mod:`.context` (the clouds and caches one registration shares),
:mod:`.steps` (the step base class), :mod:`.global_estimators` and :mod:`.icp` (the
steps), :mod:`.symmetry`, :mod:`.pipeline` (chains and ``register``), :mod:`.scoring`
(recall for model selection) and :mod:`.multiway` (pose graphs over many scans).
"""

from .context import RegistrationContext, RegistrationWarning
from .global_estimators import FGRGlobal, RANSACGlobal, SVDGlobal
from .icp import GeneralizedICP, MultiScaleICP, PointToPlaneICP, PointToPointICP
from .multiway import MultiwayResult, register_multiway
from .pipeline import RegistrationPipeline, RegistrationResult, register
from .scoring import registration_recall, registration_scorer
from .settings import RegistrationSettings
from .steps import RegistrationStep, StepResult
from .symmetry import SymmetryCheck

__all__ = [
    "FGRGlobal",
    "GeneralizedICP",
    "MultiScaleICP",
    "MultiwayResult",
    "PointToPlaneICP",
    "PointToPointICP",
    "RANSACGlobal",
    "RegistrationContext",
    "RegistrationPipeline",
    "RegistrationResult",
    "RegistrationSettings",
    "RegistrationStep",
    "RegistrationWarning",
    "SVDGlobal",
    "StepResult",
    "SymmetryCheck",
    "register",
    "register_multiway",
    "registration_recall",
    "registration_scorer",
]
