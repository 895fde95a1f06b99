"""``o3d-rpointhop view``: a saved result, or clouds and a transform, in the browser."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from ._common import CommandError

__all__ = ["add_parser", "add_view", "run"]


def add_view(parser: argparse.ArgumentParser) -> None:
    """``--view`` and ``--port`` for a command whose result can be looked at."""
    parser.add_argument(
        "--view",
        action="store_true",
        help="then serve the result as an interactive 3D page (viser) until Ctrl-C",
    )
    parser.add_argument("--port", type=int, default=8080, help="port of --view (default 8080)")
    parser.add_argument(
        "--host",
        default="127.0.0.1",
        help="address of --view (default 127.0.0.1; 0.0.0.0 to reach it from elsewhere)",
    )


def add_parser(commands) -> None:
    p = commands.add_parser(
        "view",
        help="look at a registration or reconstruction in the browser",
        description="Serve an interactive 3D page (viser; its client ships in its wheel, "
        "no network needed): RESULT is a file saved by 'register --result' (then give the "
        "source and target clouds) or 'reconstruct --result' (then give every scan, in "
        "order), or a 4x4 text matrix (then give source and target). Clouds can be toggled; "
        "the panel shows the result's numbers and flags.",
    )
    p.add_argument("result", help="saved result (.json) or 4x4 transformation (.txt)")
    p.add_argument("clouds", nargs="+", help="the clouds the result is about, in order")
    p.add_argument("--port", type=int, default=8080, help="port (default 8080)")
    p.add_argument(
        "--host", default="127.0.0.1", help="address (0.0.0.0 to reach it from elsewhere)"
    )
    p.set_defaults(func=run)


def _kind(path: Path) -> str | None:
    try:
        body = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError):
        return None
    return body.get("kind") if isinstance(body, dict) else None


def run(args: argparse.Namespace) -> int:
    from ..io import read_cloud
    from ..poses import read_matrix
    from ..registration import MultiwayResult, RegistrationResult
    from ..viewer import show_multiway, show_registration

    path = Path(args.result)
    if not path.is_file():
        raise CommandError(f"{path}: no such file")
    clouds = [read_cloud(c) for c in args.clouds]
    kind = _kind(path) if path.suffix.lower() == ".json" else None
    serve = dict(host=args.host, port=args.port)
    if kind == "MultiwayResult":
        names = [Path(c).name for c in args.clouds]
        show_multiway(clouds, MultiwayResult.load(path), names=names, **serve)
        return 0
    if len(clouds) != 2:
        raise CommandError(f"a pair result needs two clouds (source, target), got {len(clouds)}")
    if kind == "RegistrationResult":
        result = RegistrationResult.load(path)
    else:
        from ..registration import evaluate

        result = evaluate(clouds[0], clouds[1], read_matrix(path))
    show_registration(clouds[0], clouds[1], result, **serve)
    return 0
