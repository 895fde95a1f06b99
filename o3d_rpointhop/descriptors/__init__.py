"""Point descriptors behind one scikit-learn interface: :class:`RPointHopTransformer`
(learned, rotation-invariant), :class:`FPFHTransformer` (Open3D's FPFH) and
:class:`DescriptorUnion` (several side by side).

Private modules, in the manner of ``sklearn.decomposition``: :mod:`._base` (what the
two point descriptors share), :mod:`._rpointhop`, :mod:`._fpfh` and :mod:`._union` (the
estimators), :mod:`._pretrained` (the shipped models), :mod:`._persistence` (the model
file format), :mod:`._identity` (what a record calls a descriptor) and the subpackage
:mod:`.pointhop` (the R-PointHop maths, free of scikit-learn).
"""

from ._base import BaseDescriptor, call_with_viewpoints
from ._fpfh import FEATURE_RADIUS_FACTOR, NORMAL_RADIUS_FACTOR, FPFHTransformer
from ._identity import descriptor_identity
from ._persistence import content_hash
from ._pretrained import PRETRAINED_COMPONENTS, PRETRAINED_MODELS
from ._rpointhop import RPointHopTransformer
from ._union import DescriptorUnion, unit_rows

__all__ = [
    "BaseDescriptor",
    "DescriptorUnion",
    "FEATURE_RADIUS_FACTOR",
    "FPFHTransformer",
    "NORMAL_RADIUS_FACTOR",
    "PRETRAINED_COMPONENTS",
    "PRETRAINED_MODELS",
    "RPointHopTransformer",
    "call_with_viewpoints",
    "content_hash",
    "descriptor_identity",
    "unit_rows",
]
