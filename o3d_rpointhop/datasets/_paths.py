"""Where the real datasets live."""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["data_home"]

ENV_VAR = "O3D_RPOINTHOP_DATA"


#: The user folder looked in when neither ``data_dir`` nor the variable is given.
USER_FOLDER = Path("~") / "o3d_rpointhop_data"


def data_home(data_dir: str | os.PathLike | None = None) -> Path:
    """Folder holding the real datasets.

    Looked up in this order:

    1. ``data_dir``, when given;
    2. the ``O3D_RPOINTHOP_DATA`` environment variable, when set;
    3. the user folder ``~/o3d_rpointhop_data``;
    4. for developers working in a checkout: ``../shared/data`` next to the checkout or
       to the working directory.

    The first two must exist when given; the others are used when they do.

    Raises
    ------
    FileNotFoundError
        If ``data_dir`` or the variable names a missing folder, or none of 3 and 4 is
        a folder.
    """
    if data_dir is not None:
        path = Path(data_dir).expanduser()
        if not path.is_dir():
            raise FileNotFoundError(f"data folder {path} does not exist")
        return path
    if os.environ.get(ENV_VAR):
        path = Path(os.environ[ENV_VAR]).expanduser()
        if not path.is_dir():
            raise FileNotFoundError(f"{ENV_VAR}={os.environ[ENV_VAR]} is not a folder")
        return path
    candidates = [
        USER_FOLDER.expanduser(),
        Path(__file__).resolve().parents[3] / "shared" / "data",
        Path.cwd().parent / "shared" / "data",
    ]
    for path in candidates:
        if path.is_dir():
            return path
    raise FileNotFoundError(
        f"no data folder found: pass data_dir=..., set {ENV_VAR}, or put the data in "
        f"{USER_FOLDER} (looked in {', '.join(str(c) for c in candidates)})"
    )
