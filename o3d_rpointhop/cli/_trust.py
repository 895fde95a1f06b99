"""Whether a command's result can be trusted: its exit status from the result's flags
and support, the one-line warnings that say why, and the inputs stored too coarsely."""

from __future__ import annotations

import logging
import warnings
from collections.abc import Sequence

from ._common import EXIT_OK, EXIT_UNRELIABLE, EXIT_UNTRUSTED

__all__ = [
    "flag_status",
    "log",
    "read_noting_precision",
    "report_reconstruction",
    "trust_problems",
    "trust_status",
]


#: Where the commands' warnings go (stderr, unless -q; see ``cli.main``).
log = logging.getLogger("o3d_rpointhop.cli")


def read_noting_precision(path: str, rounded: list[str]):
    """``io.read_cloud(path)``, with ``path`` added to ``rounded`` (and said in one
    line) when the file stored coordinates too coarse for the cloud."""
    from ..io import PrecisionWarning, read_cloud

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", PrecisionWarning)
        cloud = read_cloud(path)
    for warning in caught:
        if issubclass(warning.category, PrecisionWarning):
            rounded.append(path)
            log.warning(str(warning.message))
        else:
            warnings.warn(warning.message, warning.category, stacklevel=2)
    return cloud


def trust_problems(result, rounded: Sequence[str] = ()) -> list[str]:
    """Why a converged, unambiguous result is not to be trusted (empty when it is):
    support under :data:`~o3d_rpointhop.registration.defaults.TRUST_SUPPORT`, or
    clouds (``rounded``: their files) whose coordinates were rounded when stored."""
    from ..registration.defaults import TRUST_SUPPORT

    problems = []
    support = result.support
    if support is not None and support < TRUST_SUPPORT:
        problems.append(
            f"little support: {support:.2%} of the matches agree with the pose, under the "
            f"{TRUST_SUPPORT:.0%} below which results are most often wrong"
        )
    problems += [f"{name} was stored with too little precision to register" for name in rounded]
    return problems


def trust_status(result, problems: Sequence[str]) -> int:
    """Exit status of a finished registration: 3 when flagged (:func:`flag_status`),
    else 4 with one warning line per problem when ``problems`` (from
    :func:`trust_problems`), else 0."""
    status = flag_status(result)
    if status != EXIT_OK or not problems:
        return status
    for problem in problems:
        log.warning(f"the result is not to be trusted: {problem}")
    return EXIT_UNTRUSTED


def flag_status(result) -> int:
    """Exit status of a finished registration: 3, with a warning on stderr, when
    flagged."""
    if not result.converged:
        log.warning(
            f"the result did not converge (fitness {result.fitness:.3f}): no overlap, or a "
            "chance alignment"
        )
        return EXIT_UNRELIABLE
    if result.ambiguous:
        log.warning(
            "the result is ambiguous: turned by 180 degrees it fits about as well (a "
            "symmetric shape or a featureless plane)"
        )
        return EXIT_UNRELIABLE
    return EXIT_OK


def report_reconstruction(summary: dict, first_scan: str) -> None:
    """What a reconstruction's summary (``MultiwayResult.as_dict``) says a user must
    know, on stderr: the frame when it is not the first scan's, every scan left out and
    why, and how many placed scans rest on edges no loop checks (-v names each)."""
    if summary["frame"] != first_scan:
        log.warning(f"{first_scan} is not placed: the poses are in {summary['frame']}'s frame")
    for name, why in summary["left_out"].items():
        log.warning(f"left out: {name}: {why}")
    unverified = summary["unverified"]
    if unverified:
        log.warning(
            f"{len(unverified)} placed scans are joined to the others by edges no loop of "
            "the pose graph checks (a wrong one misplaces them): 'unverified' in --poses; -v "
            "names them"
        )
    for name, why in unverified.items():
        log.info(f"unverified: {name}: {why}")
