"""Registration steps, one module per algorithm: the global estimators :mod:`.svd`
(the paper's one-shot SVD), :mod:`.ransac` (with its vectorised kernel in
:mod:`._ransac`), :mod:`.fgr` and :mod:`.consensus` (a correspondence graph, kernel in
:mod:`._consensus`), the refinements in :mod:`.icp`, and
:mod:`.symmetry`; :mod:`._base` holds the step base class and :mod:`._global` what the
global steps share. The consensus's graph kernels (:func:`compatibility_graphs`,
:func:`consensus_sets`) are exported for peers built on the same graph (SC2-PCR in
:mod:`o3d_rpointhop.evaluation.sc2pcr`)."""

from ._base import OPTIONAL_DISTANCE, RegistrationStep
from ._consensus import compatibility_graphs, consensus_sets
from ._global import DESCRIPTOR, MATCHER, GlobalStep
from .consensus import ConsensusGlobal
from .fgr import FGRGlobal, tuple_test
from .icp import GeneralizedICP, MultiScaleICP, PointToPlaneICP, PointToPointICP
from .ransac import RANSACGlobal
from .svd import SVDGlobal
from .symmetry import SymmetryCheck

__all__ = [
    "DESCRIPTOR",
    "MATCHER",
    "OPTIONAL_DISTANCE",
    "ConsensusGlobal",
    "FGRGlobal",
    "GeneralizedICP",
    "GlobalStep",
    "MultiScaleICP",
    "PointToPlaneICP",
    "PointToPointICP",
    "RANSACGlobal",
    "RegistrationStep",
    "SVDGlobal",
    "SymmetryCheck",
    "compatibility_graphs",
    "consensus_sets",
    "tuple_test",
]
