"""o3d-rpointhop: unsupervised, rotation-invariant R-PointHop point descriptors for Open3D."""

from ._version import __version__
from .fpfh import FPFHTransformer
from .rpointhop import RPointHopTransformer

__all__ = ["FPFHTransformer", "RPointHopTransformer", "__version__"]
