"""Where the real datasets live."""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["data_home"]

ENV_VAR = "O3D_RPOINTHOP_DATA"


def data_home(data_dir: str | os.PathLike | None = None) -> Path:
    """Folder holding the real datasets.

    Looked up in this order: ``data_dir``; the ``O3D_RPOINTHOP_DATA`` environment
    variable; ``../shared/data`` next to the working directory or to this checkout.

    Raises
    ------
    FileNotFoundError
        If none of these is a folder.
    """
    if data_dir is not None:
        path = Path(data_dir).expanduser()
        if not path.is_dir():
            raise FileNotFoundError(f"data folder {path} does not exist")
        return path
    candidates = []
    if os.environ.get(ENV_VAR):
        candidates.append(Path(os.environ[ENV_VAR]).expanduser())
    candidates.append(Path.cwd().parent / "shared" / "data")
    candidates.append(Path(__file__).resolve().parents[3] / "shared" / "data")
    for path in candidates:
        if path.is_dir():
            return path
    raise FileNotFoundError(
        "no data folder found: pass data_dir=..., or set O3D_RPOINTHOP_DATA, or place the "
        f"data in ../shared/data (looked in {', '.join(str(c) for c in candidates)})"
    )
