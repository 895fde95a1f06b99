"""Leaves of the package: input validation, parallel maps, progress bars, thread limits
and small geometry helpers. Nothing here imports any other part of ``o3d_rpointhop``."""
