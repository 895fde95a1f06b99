"""Registration: global estimates from descriptors, then ICP refinement chains.

Modules, one concept each: :mod:`.defaults` (the descriptor and global cloud size used
when none is given), :mod:`.settings` (the resolution and every distance derived from
it), :mod:`.context` (the clouds and caches one registration shares),
:mod:`.correspondences` (the nearest-descriptor search), :mod:`.matching` (the matcher
that owns every matching option), :mod:`.result` (what a registration
returns), :mod:`.checks` (refused input), :mod:`.flags` (the result's flags), the steps in
:mod:`.steps`, :mod:`.pipeline` (chains and ``register``), :mod:`.evaluate` (scoring a given
transformation), :mod:`.scoring` (recall for
model selection) and :mod:`.multiway` (pose graphs over many scans).
"""

from .checks import RegistrationWarning
from .context import RegistrationContext
from .correspondences import Correspondences, find_correspondences
from .evaluate import evaluate
from .matching import Matcher, PooledMatcher
from .multiway import register_multiway
from .pipeline import RegistrationPipeline, register
from .result import MultiwayResult, RegistrationResult, StepResult
from .scoring import registration_recall, registration_scorer
from .settings import RegistrationSettings
from .steps import (
    ConsensusGlobal,
    FGRGlobal,
    GeneralizedICP,
    MultiScaleICP,
    PointToPlaneICP,
    PointToPointICP,
    RANSACGlobal,
    RegistrationStep,
    SVDGlobal,
    SymmetryCheck,
)

__all__ = [
    "ConsensusGlobal",
    "Correspondences",
    "FGRGlobal",
    "GeneralizedICP",
    "Matcher",
    "MultiScaleICP",
    "MultiwayResult",
    "PointToPlaneICP",
    "PointToPointICP",
    "PooledMatcher",
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
    "evaluate",
    "find_correspondences",
    "register",
    "register_multiway",
    "registration_recall",
    "registration_scorer",
]
