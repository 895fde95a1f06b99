"""The R-PointHop maths, free of scikit-learn: sampling (farthest points, Poisson disks),
local reference frames, octant pooling, scene attributes, the Saab transform, the
per-cloud hop geometry and the fitted hop tree (fit / forward / describe).

Modules: :mod:`._neighbors` (k-nearest-neighbour search), :mod:`._sampling`,
:mod:`._frames`, :mod:`._octants`, :mod:`._attributes`, :mod:`._saab`, :mod:`._config`
(the hop parameters), :mod:`._geometry` (a cloud's hop structure, in compiled passes),
:mod:`._pooling` (the compiled hops from hop 2 on), :mod:`._turns` (the descriptors
under frames turned about their normals) and :mod:`._tree`.
"""

from ._config import SAMPLING_METHODS, HopConfig
from ._geometry import CloudGeometry, build_geometry, cloud_frames
from ._octants import POOLINGS
from ._tree import HopTree
from ._turns import N_TURNS_ALLOWED

__all__ = [
    "N_TURNS_ALLOWED",
    "POOLINGS",
    "SAMPLING_METHODS",
    "CloudGeometry",
    "HopConfig",
    "HopTree",
    "build_geometry",
    "cloud_frames",
]
