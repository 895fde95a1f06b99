"""What every command shares: exit statuses, the one-line error, options declared once,
and the model and descriptor a command is given."""

from __future__ import annotations

import argparse

PROG = "o3d-rpointhop"
#: The shipped models' names (``descriptors.PRETRAINED_MODELS``, written out so that
#: building the parser loads no library; a test keeps the two equal).
SHIPPED_MODELS = ("modelnet40", "object", "scene", "scene-fpfh")
#: The trajectory formats (``poses.POSE_FORMATS``, written out for the same reason).
POSE_FORMATS = ("kitti", "tum", "3dmatch")

#: Exit statuses (listed in ``--help``).
EXIT_OK, EXIT_ERROR, EXIT_USAGE, EXIT_UNRELIABLE, EXIT_UNTRUSTED = 0, 1, 2, 3, 4
EXIT_CODES = f"""exit status:
  {EXIT_OK}  success
  {EXIT_ERROR}  error: a missing, empty, damaged or unreadable file, a directory given as a
     file, NaN coordinates, too few points, degenerate geometry, an output that exists
     as a folder or exceeds the size limit without --force; one line on stderr says which
     (--debug shows the traceback instead)
  {EXIT_USAGE}  usage error (unknown option, bad value, a --config / --set setting refused;
     checked before any input is read)
  {EXIT_UNRELIABLE}  register/demo finished, but the result is flagged: not converged (no
     overlap, or a chance alignment) or ambiguous (a symmetric shape); reconstruct
     finished with unconnected scans left out; outputs are written, and stderr says
     which
  {EXIT_UNTRUSTED}  register finished and converged, but the result is not to be trusted: too
     few of its matches agree with it (support under 0.01) or a cloud's coordinates were
     rounded before reading (float32 at survey coordinates); outputs are written, and
     stderr says why in one line"""
#: Largest output written without --force.
MAX_OUTPUT_BYTES = 512 * 1024**2
#: What ``--descriptor`` names.
DESCRIPTORS = ("rpointhop", "fpfh", "rpointhop+fpfh")


class CommandError(Exception):
    """A failure to report as one line on stderr with exit status 1."""


class UsageError(CommandError):
    """A bad option or setting (an unknown section or parameter, a value the step
    refuses), reported as one line on stderr with exit status 2, before any input is
    read."""


def check_size(
    path: str,
    nbytes: int,
    force: bool,
    hint: str = "shorten the descriptor with --n-components",
) -> None:
    """Refuse an output over :data:`MAX_OUTPUT_BYTES` unless ``force``."""
    if nbytes > MAX_OUTPUT_BYTES and not force:
        raise CommandError(
            f"{path}: would write {nbytes / 1024**2:,.0f} MB (limit {MAX_OUTPUT_BYTES // 1024**2} "
            f"MB without --force); pass --force, or {hint}"
        )


def cloud_bytes(cloud) -> int:
    """About what writing an Open3D cloud takes: float64 points and normals, byte
    colours."""
    per_point = 24 + (24 if cloud.has_normals() else 0) + (3 if cloud.has_colors() else 0)
    return per_point * len(cloud.points)


def add_force(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--force",
        action="store_true",
        help=f"write outputs over {MAX_OUTPUT_BYTES // 1024**2} MB",
    )


def auto_or(convert, what: str, valid, problem: str):
    """An argparse type: ``"auto"``, or ``convert(text)`` when ``valid`` accepts it."""

    def parse(text: str):
        if text == "auto":
            return text
        try:
            value = convert(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected 'auto' or {what}, got {text!r}") from None
        if not valid(value):
            raise argparse.ArgumentTypeError(f"{problem}, got {text!r}")
        return value

    return parse


#: ``--voxel-size``: "auto" or a positive length.
positive_or_auto = auto_or(float, "a number", lambda v: v > 0, "voxel size must be positive")
#: ``--n-global-points``: "auto" or a count of at least 3.
global_points = auto_or(int, "a count", lambda v: v >= 3, "need at least 3 global points")


# --------------------------------------------------------------------------- options
def add_model(parser: argparse.ArgumentParser, default: str) -> None:
    """``--model``: a model file, or a shipped model by name."""
    parser.add_argument(
        "--model",
        help=f"R-PointHop model file written by 'fit', or a shipped model: "
        f"{', '.join(SHIPPED_MODELS)} (default: {default})",
    )


def add_descriptor(parser: argparse.ArgumentParser) -> None:
    """``--descriptor``: R-PointHop (``--model``) or FPFH."""
    parser.add_argument(
        "--descriptor",
        choices=DESCRIPTORS,
        help="rpointhop (the model of --model; the default), fpfh (radii from the "
        "resolution) or rpointhop+fpfh (both side by side, FPFH weighing [descriptor] "
        "fpfh_weight, 0.7)",
    )


def _xyz(text: str) -> list[float] | None:
    """``"x,y,z"`` as three floats, or None."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        return None
    return values if len(values) == 3 else None


def vector(text: str) -> list[float]:
    """An argparse type: one direction or position ``x,y,z``."""
    values = _xyz(text)
    if values is None:
        raise argparse.ArgumentTypeError(f"expected 'x,y,z', got {text!r}")
    return values


def _viewpoints(text: str):
    """``--viewpoints``: ``auto``, ``origin``, ``none``, or one or more positions
    ``x,y,z`` separated by ``;`` (one per cloud, in that cloud's coordinates)."""
    if text in ("auto", "origin", "none"):
        return text
    views = [_xyz(part) for part in text.split(";")]
    if any(v is None for v in views):
        raise argparse.ArgumentTypeError(
            f"expected 'auto', 'origin', 'none' or positions 'x,y,z;x,y,z', got {text!r}"
        )
    return views


def _given_viewpoints(text: str):
    """``--viewpoints`` of a command that chooses no model: ``auto`` is refused and
    ``none`` is None."""
    views = _viewpoints(text)
    if views == "auto":
        raise argparse.ArgumentTypeError("'auto' applies to register and reconstruct")
    return None if views == "none" else views


def add_viewpoints(parser: argparse.ArgumentParser, clouds: str, chosen: bool = False) -> None:
    """``--viewpoints``: where the sensors stood; ``chosen``: the command chooses them
    with the model (``auto``, its default)."""
    where = (
        "where the sensors stood: 'origin' (every cloud is in its sensor's frame: depth "
        f"images, LiDAR sweeps, 3DMatch fragments), 'x,y,z;...', one per {clouds}, in its "
        "own coordinates (normals and local frames then face the sensor), 'none' (no sensor "
        "known)"
    )
    if chosen:
        where += " or 'auto' (the default: chosen with the model when --model is auto, else none)"
    else:
        where += " (the default)"
    parser.add_argument(
        "--viewpoints", type=_viewpoints if chosen else _given_viewpoints, help=where
    )


def add_data(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--data",
        help="data folder (default: $O3D_RPOINTHOP_DATA, else ~/o3d_rpointhop_data, else "
        "../shared/data beside the checkout)",
    )


def add_seed(parser: argparse.ArgumentParser, default: int | None = 0) -> None:
    parser.add_argument(
        "--seed", type=int, default=default, help="seeds every random choice (default: 0)"
    )


def add_config(parser: argparse.ArgumentParser) -> None:
    """``--config FILE`` and ``--set section.parameter=value``."""
    parser.add_argument(
        "--config",
        help="TOML file: one section per step and [settings], keys are the library's "
        "parameter names ('o3d-rpointhop config' prints every default); flags win over it",
    )
    parser.add_argument(
        "--set",
        action="append",
        metavar="SECTION.PARAMETER=VALUE",
        help="one setting, e.g. ransac.max_iteration=100000 or settings.icp_factors=[2.0,0.5] "
        "(repeatable; wins over --config)",
    )


def add_json(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="print the full result as JSON")


# --------------------------------------------------------------------------- inputs
def load_model(name: str | None, n_components: int | None = None):
    """A model file, a shipped model by name, else the paper's ModelNet40 model; on
    ``n_components`` axes when given (a shipped model otherwise comes as
    ``pretrained(name)`` gives it)."""
    from ..descriptors import RPointHopTransformer

    if name is None or name in SHIPPED_MODELS:
        return RPointHopTransformer.pretrained(
            name or "modelnet40", n_components="default" if n_components is None else n_components
        )
    model = RPointHopTransformer.load(name)
    if n_components is not None:
        model.set_params(n_components=n_components)
    return model
