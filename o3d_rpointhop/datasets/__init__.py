"""Sample data: synthetic shapes, and loaders for public benchmark datasets.

The project ships no third-party data. The loaders read it from a folder the user
points to (``data_dir=``), the ``O3D_RPOINTHOP_DATA`` environment variable, or
``../shared/data``; see :func:`data_home`.
"""

from ._paths import data_home
from .modelnet40 import ModelNet40, load_modelnet40, normalize_unit_sphere
from .synthetic import make_blob, make_object

__all__ = [
    "ModelNet40",
    "data_home",
    "load_modelnet40",
    "make_blob",
    "make_object",
    "normalize_unit_sphere",
]
