"""Several descriptors side by side, each scaled to unit length and weighted (in the
manner of scikit-learn's ``FeatureUnion``)."""

from __future__ import annotations

from numbers import Real
from typing import Any

import numpy as np
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.preprocessing import normalize
from sklearn.utils.validation import check_is_fitted

from ._base import call_with_viewpoints as _call

__all__ = ["DescriptorUnion", "unit_rows"]


def unit_rows(features: Any) -> np.ndarray:
    """Descriptors scaled to unit length along their last axis, so that their Euclidean
    distances order pairs as their cosine distances do (a zero descriptor stays zero).

    Parameters
    ----------
    features : array-like of shape (..., dim)
        Descriptors, one per row (``(n_turns, n, dim)`` for turned descriptors).

    Returns
    -------
    ndarray of the same shape and floating dtype
    """
    features = np.asarray(features)
    flat = features.reshape(-1, features.shape[-1])
    return normalize(flat, norm="l2", copy=True).reshape(features.shape)


class DescriptorUnion(TransformerMixin, BaseEstimator):
    """Several point descriptors side by side: each point's row of every part, scaled to
    unit length and weighted, concatenated.

    Two descriptors that fail on different points match better together than either
    alone: R-PointHop's learned, frame-based descriptor and FPFH's angle histograms
    disagree on which walls and table tops look alike. Scaling each part's rows to unit
    length makes the weights the parts' shares of a distance, whatever their own scales
    (an FPFH row sums to 600, R-PointHop's rows are projections of centred data).
    The union has the interface of its parts (``fit``, ``transform`` with
    ``viewpoints``, one row per input point in input order), so it is given to
    :func:`~o3d_rpointhop.register`, to a global step's ``descriptor`` or to a
    scikit-learn pipeline as either part would be.

    Parameters
    ----------
    transformer_list : list of (str, transformer)
        The parts, each named (as in scikit-learn's ``FeatureUnion``): descriptors of
        this library or any transformer of point clouds with one row per point.
    transformer_weights : dict of str to float, default=None
        Each named part's weight (positive); parts not named weigh 1.

    Attributes
    ----------
    n_features_in_ : int
        Always 3.
    n_features_out_ : int
        The sum of the parts' widths.
    registration_points_, registration_global_method_ : int or str
        What the first part that states them tells :func:`~o3d_rpointhop.register`
        (the shipped scene model: 4096 points, the consensus); absent when no part
        states them.

    Notes
    -----
    ``fit`` fits every part in place, as ``FeatureUnion`` does: give it a fitted
    (pretrained) part and do not call ``fit`` to keep that part as it is, or wrap the
    part in ``sklearn.frozen.FrozenEstimator`` where something else fits and clones
    (``RegistrationPipeline.fit``, ``GridSearchCV``).
    :meth:`transform` works as soon as every part can transform (FPFH learns nothing).
    With frame turns (:meth:`transform_turns`), the parts without local frames (no
    ``transform_turns``, as FPFH) are repeated under every turn.

    Examples
    --------
    >>> from o3d_rpointhop import DescriptorUnion, FPFHTransformer, RPointHopTransformer
    >>> union = DescriptorUnion(
    ...     [("rpointhop", RPointHopTransformer.pretrained("scene")), ("fpfh", FPFHTransformer())],
    ...     transformer_weights={"fpfh": 0.7},
    ... )
    >>> # register(source, target, union, viewpoints="origin")
    """

    def __init__(
        self,
        transformer_list: list[tuple[str, Any]],
        *,
        transformer_weights: dict[str, float] | None = None,
    ) -> None:
        self.transformer_list = transformer_list
        self.transformer_weights = transformer_weights

    # -- parameters -------------------------------------------------------------------

    def validate(self) -> None:
        """Check the parts and their weights without describing (each part checks its
        own parameters when it is fitted or describes).

        Raises
        ------
        ValueError, TypeError
            For a malformed part list, a part without ``transform`` or a bad weight.
        """
        self._parts()

    def _parts(self) -> list[tuple[str, Any, float]]:
        """The checked parts: ``(name, transformer, weight)``."""
        parts = self.transformer_list
        if not isinstance(parts, (list, tuple)) or not parts:
            raise ValueError(
                "transformer_list must be a non-empty list of (name, transformer) pairs, "
                f"got {parts!r}"
            )
        names = []
        for item in parts:
            if not (isinstance(item, tuple) and len(item) == 2 and isinstance(item[0], str)):
                raise ValueError(f"every part must be a (name, transformer) pair, got {item!r}")
            if not hasattr(item[1], "transform"):
                raise TypeError(f"part {item[0]!r} has no transform: {item[1]!r}")
            names.append(item[0])
        if len(set(names)) != len(names) or any("__" in n or not n for n in names):
            raise ValueError(f"part names must be unique, non-empty, without '__': {names}")
        weights = dict(self.transformer_weights or {})
        unknown = sorted(set(weights) - set(names))
        if unknown:
            raise ValueError(f"transformer_weights names no part: {unknown} (parts: {names})")
        for name, weight in weights.items():
            number = isinstance(weight, Real) and not isinstance(weight, bool)
            if not (number and 0 < weight < np.inf):
                raise ValueError(f"the weight of {name!r} must be positive and finite: {weight!r}")
        return [(name, part, float(weights.get(name, 1.0))) for name, part in parts]

    # -- fitting and describing ---------------------------------------------------------

    def fit(self, X: Any, y: Any = None, viewpoints: Any = None) -> DescriptorUnion:
        """Fit every part on the same clouds (in place).

        Parameters
        ----------
        X : point cloud(s)
            As the parts' ``fit`` takes them.
        y : None
            Passed on (descriptors ignore it).
        viewpoints : None, "origin" or positions, default=None
            Passed to every part's ``fit``.

        Returns
        -------
        self : DescriptorUnion
        """
        for _, part, _ in self._parts():
            if viewpoints is None:
                part.fit(X, y)
            else:
                part.fit(X, y, viewpoints=viewpoints)
        self.n_features_in_ = 3
        self.n_features_out_ = self._width()
        return self

    def fit_transform(self, X: Any, y: Any = None, viewpoints: Any = None) -> Any:
        """:meth:`fit` then :meth:`transform`, with the same ``viewpoints``."""
        return self.fit(X, y, viewpoints=viewpoints).transform(X, viewpoints=viewpoints)

    def transform(self, X: Any, viewpoints: Any = None) -> np.ndarray | list[np.ndarray]:
        """Every part's descriptors of every point, each row scaled to unit length and
        weighted, side by side in the order of ``transformer_list``.

        Parameters
        ----------
        X : array-like of shape (n_points, 3) or (n_clouds, n_points, 3), \
                open3d.geometry.PointCloud, or list of those
            As the parts take them.
        viewpoints : None, "origin", array-like of shape (3,) or (n_clouds, 3), \
                default=None
            Where the sensor stood, passed to every part (see
            :meth:`RPointHopTransformer.transform
            <o3d_rpointhop.RPointHopTransformer.transform>`).

        Returns
        -------
        descriptors : ndarray of shape (n_points, ``n_features_out_``), a list of them for a
            list input, or an ndarray of shape (n_clouds, n_points, ``n_features_out_``)
            for a 3-D array input; float32.

        Raises
        ------
        ValueError
            If the parts answer different numbers of rows, or the parameters are bad.
        TypeError
            If viewpoints are given and a part's ``transform`` takes none.
        """
        answers = [
            (_call(part.transform, X, viewpoints), weight) for _, part, weight in self._parts()
        ]
        return self._joined(answers)

    def transform_turns(
        self, X: Any, n_turns: int = 4, viewpoints: Any = None
    ) -> np.ndarray | list[np.ndarray]:
        """Every point's union under its local frames turned about their normals
        (:meth:`RPointHopTransformer.transform_turns
        <o3d_rpointhop.RPointHopTransformer.transform_turns>`): the parts with local
        frames are turned, the others (no ``transform_turns``: FPFH) repeated under
        every turn.

        Parameters
        ----------
        X : point cloud(s)
            As in :meth:`transform`.
        n_turns : {1, 2, 4}, default=4
            As the parts' ``transform_turns`` takes it.
        viewpoints : None, "origin" or positions, default=None
            As in :meth:`transform`.

        Returns
        -------
        descriptors : ndarray of shape (n_turns, n_points, ``n_features_out_``), or a list
            of them for a list input, or an ndarray of shape
            (n_clouds, n_turns, n_points, ``n_features_out_``) for a 3-D array input

        Raises
        ------
        TypeError
            If no part has local frames to turn.
        """
        parts = self._parts()
        if not any(hasattr(part, "transform_turns") for _, part, _ in parts):
            raise TypeError(
                "frame turns were asked for, but no part of the union has local frames "
                "to turn (no transform_turns): add an RPointHopTransformer, or use "
                "Matcher(frame_turns=1)"
            )
        answers = []
        for _, part, weight in parts:
            if hasattr(part, "transform_turns"):
                answer = _call(part.transform_turns, X, viewpoints, n_turns)
            else:
                answer = _repeated(_call(part.transform, X, viewpoints), n_turns)
            answers.append((answer, weight))
        return self._joined(answers)

    def _joined(self, answers: list[tuple[Any, float]]) -> np.ndarray | list[np.ndarray]:
        """The parts' answers (one form: arrays or lists of arrays), scaled and joined
        along the last axis."""
        first = answers[0][0]
        if isinstance(first, list):
            if any(not isinstance(a, list) or len(a) != len(first) for a, _ in answers):
                raise ValueError("the parts answered different numbers of clouds")
            return [_join([(a[k], w) for a, w in answers]) for k in range(len(first))]
        return _join(answers)

    # -- what the union tells the rest of the library -------------------------------------

    def at_resolution(self, voxel_size: float, settings: Any = None) -> DescriptorUnion:
        """The union a registration at ``voxel_size`` describes with: every part's own
        ``at_resolution`` (FPFH's ``"auto"`` radii), or itself when no part changes."""
        bound = []
        for name, part, _ in self._parts():
            at = getattr(part, "at_resolution", None)
            bound.append((name, part if at is None else at(voxel_size, settings)))
        if all(b is p for (_, b), (_, p) in zip(bound, self.transformer_list, strict=True)):
            return self
        copy = DescriptorUnion(bound, transformer_weights=self.transformer_weights)
        copy.__dict__.update({k: v for k, v in vars(self).items() if k.endswith("_")})
        return copy

    def _stated(self, attribute: str) -> Any:
        for _, part in self.transformer_list:
            value = getattr(part, attribute, None)
            if value is not None:
                return value
        raise AttributeError(f"no part of the union states {attribute}")

    @property
    def registration_points_(self) -> int:
        return self._stated("registration_points_")

    @property
    def registration_global_method_(self) -> str:
        return self._stated("registration_global_method_")

    def _width(self) -> int:
        widths = []
        for name, part, _ in self._parts():
            width = getattr(part, "n_features_out_", None)
            if width is None:
                width = getattr(part, "_n_features_out", None)
            if width is None:
                raise AttributeError(f"part {name!r} does not say its width (n_features_out_)")
            widths.append(int(width))
        return sum(widths)

    def get_feature_names_out(self, input_features: Any = None) -> np.ndarray:
        """Each part's output names, prefixed by the part's name (``"fpfh__fpfhtransformer0"``).

        Parameters
        ----------
        input_features : None
            Ignored (the input is always x, y, z).

        Returns
        -------
        ndarray of str
        """
        check_is_fitted(self, "n_features_out_")
        names = []
        for name, part, _ in self._parts():
            names.extend(f"{name}__{n}" for n in part.get_feature_names_out())
        return np.asarray(names, dtype=object)

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.three_d_array = True
        tags.transformer_tags.preserves_dtype = []
        return tags


def _repeated(answer: Any, n_turns: int) -> Any:
    """A part's descriptors without turns, repeated under ``n_turns`` turns: a new axis
    before each cloud's rows (the first of one cloud's, the second of a stack's)."""
    if isinstance(answer, list):
        return [_repeated(a, n_turns) for a in answer]
    answer = np.asarray(answer)
    axis = answer.ndim - 2
    answer = np.expand_dims(answer, axis)
    shape = list(answer.shape)
    shape[axis] = n_turns
    return np.broadcast_to(answer, shape)


def _join(blocks: list[tuple[Any, float]]) -> np.ndarray:
    """Blocks of one cloud (the same leading shape), each scaled and weighted, joined."""
    arrays = [np.asarray(a) for a, _ in blocks]
    leading = {a.shape[:-1] for a in arrays}
    if len(leading) != 1:
        raise ValueError(
            f"the parts answered different numbers of rows: {[a.shape for a in arrays]}"
        )
    scaled = [
        weight * unit_rows(a.astype(np.float32, copy=False))
        for a, (_, weight) in zip(arrays, blocks, strict=True)
    ]
    return np.concatenate(scaled, axis=-1)
