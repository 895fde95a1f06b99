"""The files a command's inputs name: folders and patterns listed in the order people
mean (``cloud_bin_3`` before ``cloud_bin_23``)."""

from __future__ import annotations

import re
from pathlib import Path

from ._common import CommandError

__all__ = ["fragment_number", "natural_key", "scan_paths"]


def fragment_number(path: str, why: str = "no gt.log record can be chosen for it") -> int:
    """The number a fragment's file name ends in (``cloud_bin_14.ply``: 14), as 3DMatch
    names its fragments and its ``gt.log`` numbers them; CommandError (saying ``why``
    the number is needed) for a name that ends in none."""
    found = re.search(r"(\d+)$", Path(path).stem)
    if found is None:
        raise CommandError(f"{path}: the name ends in no number, so {why}")
    return int(found[1])


def natural_key(path: str) -> tuple:
    """Sort key of a file name in the order people mean: runs of digits compared as
    numbers (``scan_9`` before ``scan_10``, ``cloud_bin_3`` before ``cloud_bin_23``),
    the rest as text, case aside; the name as given breaks what remains tied."""
    parts = re.split(r"(\d+)", str(path))
    return [(0, int(p), "") if p.isdigit() else (1, 0, p.casefold()) for p in parts], str(path)


def scan_paths(inputs: list[str]) -> list[str]:
    """The scan files the inputs name: a file as given; a folder, every file in it whose
    extension ``read_cloud`` reads as points (text tables left out: a folder of scans
    often holds notes or poses too), in natural order (:func:`natural_key`); a pattern
    with ``*``, ``?`` or ``[`` that is not a file, the files it matches, in natural
    order. CommandError for a folder or pattern that names no scan, or a path that
    does not exist."""
    import glob

    from ..io import READ_FORMATS

    suffixes = {s for s in READ_FORMATS if s not in (".txt", ".csv")}
    out = []
    for item in inputs:
        path = Path(item)
        if path.is_dir():
            found = sorted(
                (str(p) for p in path.iterdir() if p.is_file() and p.suffix.lower() in suffixes),
                key=natural_key,
            )
            if not found:
                raise CommandError(
                    f"{item}: a folder without scan files ({', '.join(sorted(suffixes))})"
                )
            out += found
        elif not path.exists() and any(c in item for c in "*?["):
            found = sorted((p for p in glob.glob(item) if Path(p).is_file()), key=natural_key)
            if not found:
                raise CommandError(f"{item}: no file matches this pattern")
            out += found
        elif not path.exists():
            raise CommandError(f"{item}: no such file or folder")
        else:
            out.append(item)
    return out
