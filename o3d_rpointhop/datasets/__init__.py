"""Sample data: synthetic shapes, and loaders for public benchmark datasets.

The project ships no third-party data. The loaders read it from a folder the user
points to (``data_dir=``), the ``O3D_RPOINTHOP_DATA`` environment variable, or
``../shared/data``; see :func:`data_home`.
"""

from ._paths import data_home
from .bunny import BUNNY_SCANS, BunnyScan, load_bunny, load_dragon, read_bun_conf
from .modelnet40 import ModelNet40, load_modelnet40, normalize_unit_sphere
from .synthetic import make_blob, make_object, make_room
from .threedmatch import FragmentPair, load_3dmatch_pairs, read_gt_info, read_gt_log

__all__ = [
    "BUNNY_SCANS",
    "BunnyScan",
    "FragmentPair",
    "ModelNet40",
    "data_home",
    "load_3dmatch_pairs",
    "load_bunny",
    "load_dragon",
    "load_modelnet40",
    "make_blob",
    "make_object",
    "make_room",
    "normalize_unit_sphere",
    "read_bun_conf",
    "read_gt_info",
    "read_gt_log",
]
