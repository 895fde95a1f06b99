"""What every benchmark records, typed: one record per method and pair (objects and
scenes) or per scan (scan sets).

The runners build these records and the summaries read their attributes; a result file
holds them as :meth:`as_dict` writes them (the fields in order, a field that does not
apply left out), and :meth:`from_dict` reads them back.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

__all__ = ["PairRecord", "ScanRecord", "ScenePairRecord", "as_rows"]


class _Record:
    """``as_dict`` / ``from_dict`` for the records below: fields in declaration order,
    optional ones (default None) left out when None."""

    _optional: frozenset = frozenset()

    def as_dict(self) -> dict:
        out = {}
        for f in fields(self):  # type: ignore[arg-type]
            value = getattr(self, f.name)
            if value is None and f.name in self._optional:
                continue
            out[f.name] = value
        return out

    @classmethod
    def from_dict(cls, row: dict) -> Any:
        names = {f.name for f in fields(cls)}  # type: ignore[arg-type]
        return cls(**{k: v for k, v in row.items() if k in names})


@dataclass
class PairRecord(_Record):
    """One method on one object pair (ModelNet40, the bunny).

    Attributes
    ----------
    rotation_error_deg, translation_error : float
        Isotropic errors against the truth.
    euler_error_deg : list of float
        The three Euler angle errors (degrees, wrapped), the paper's measure.
    translation_error_xyz : list of float
        The translation error per axis.
    seconds : float
    pair : str or None
        The pair's name.
    symmetric : bool or None
        Whether the estimate is a symmetry of the shape (None: not checked).
    chamfer : float or None
        RPM-Net's modified Chamfer distance (:func:`~.metrics.modified_chamfer`; None:
        the protocol keeps no whole shape to measure it against).
    diagnostics : dict or None
        What the global step saw (:func:`~.diagnostics.choice_diagnostics`: its matches'
        share the truth explains, its verified hypotheses); None for a method that does
        not run through ``register()``.
    """

    rotation_error_deg: float
    translation_error: float
    euler_error_deg: list
    translation_error_xyz: list
    seconds: float = 0.0
    pair: str | None = None
    symmetric: bool | None = None
    chamfer: float | None = None
    diagnostics: dict | None = None

    _optional = frozenset({"pair", "symmetric", "chamfer", "diagnostics"})


@dataclass
class ScenePairRecord(_Record):
    """One method on one 3DMatch fragment pair, in the pair's original frames.

    Attributes
    ----------
    pair, scene : str
    overlap : float or None
    rmse : float
        The official error (Choi et al.) against ``gt.info``.
    registered : bool
        ``rmse`` below 0.2 m.
    registered_re_te : bool
        Rotation error below 15 deg and translation error below 30 cm.
    claimed : bool or None
        Whether the method claimed its result (None: it claims nothing).
    seconds, rotation_error_deg, translation_error : float
    transformation : list
        The estimate (4 x 4, rounded to 12 decimals).
    diagnostics : dict or None
        As :class:`PairRecord`'s.
    """

    pair: str
    scene: str
    overlap: float | None
    rmse: float
    registered: bool
    registered_re_te: bool
    claimed: bool | None
    seconds: float
    rotation_error_deg: float
    translation_error: float
    transformation: list
    diagnostics: dict | None = None

    _optional = frozenset({"diagnostics"})


@dataclass
class ScanRecord(_Record):
    """One scan of a scan set rebuilt by one method.

    Attributes
    ----------
    scan : str
    placed : bool
        Whether the method gave the scan a pose.
    rotation_error_deg, mean_point_error : float or None
        Against the scan's true pose (None for a scan not placed).
    """

    scan: str
    placed: bool
    rotation_error_deg: float | None = None
    mean_point_error: float | None = None

    _optional = frozenset({"rotation_error_deg", "mean_point_error"})

    def within(self, tolerance: tuple[float, float]) -> bool:
        """Placed within ``(degrees, distance)`` of its true pose."""
        return (
            self.placed
            and self.rotation_error_deg < tolerance[0]
            and self.mean_point_error < tolerance[1]
        )


def as_rows(records: dict) -> dict:
    """``{method: [record, ...]}`` as a result file holds it: ``{method: [dict, ...]}``."""
    return {method: [r.as_dict() for r in recs] for method, recs in records.items()}
