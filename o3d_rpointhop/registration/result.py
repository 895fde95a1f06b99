"""What a registration returns: one :class:`StepResult` per step, and the
:class:`RegistrationResult` of the whole chain (Open3D's names throughout)."""

from __future__ import annotations

import json
import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import open3d as o3d

from ..open3d_interop import to_point_cloud

__all__ = [
    "SCAN_COLOURS",
    "UNCOLOURED",
    "MultiwayResult",
    "RegistrationResult",
    "StepResult",
    "read_json",
    "write_json",
]

reg = o3d.pipelines.registration

#: Format of the files :meth:`RegistrationResult.save` and ``MultiwayResult.save`` write.
RESULT_FORMAT = 1


def _plain(value: Any) -> Any:
    """numpy values as JSON's own types (``json.dump``'s ``default``)."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"cannot write {type(value).__name__} to JSON")


def write_json(
    path: str | os.PathLike, kind: str, body: dict, provenance: dict | None = None
) -> None:
    """``body`` as a JSON file tagged with ``kind`` and :data:`RESULT_FORMAT`, with
    ``provenance`` when given."""
    extra = {} if provenance is None else {"provenance": provenance}
    text = json.dumps({"kind": kind, "format": RESULT_FORMAT, **body, **extra}, default=_plain)
    Path(path).write_text(text)


def read_json(path: str | os.PathLike, kind: str) -> dict:
    """The body of a file :func:`write_json` wrote as ``kind``; ValueError otherwise."""
    try:
        body = json.loads(Path(path).read_text())
    except json.JSONDecodeError as exc:
        # A saved result is one JSON object: text that does not close it was cut short.
        text = exc.doc.rstrip()
        cut = text.startswith("{") and not text.endswith("}")
        where = "cut short" if cut else f"damaged at line {exc.lineno}"
        raise ValueError(f"{path}: not a readable saved result (JSON {where}: {exc.msg})") from None
    except UnicodeDecodeError:
        raise ValueError(f"{path}: not a saved result (not UTF-8 text)") from None
    if not isinstance(body, dict) or body.get("kind") != kind:
        found = body.get("kind") if isinstance(body, dict) else None
        raise ValueError(f"{path}: not a saved {kind} (found {found!r})")
    if body.get("format") != RESULT_FORMAT:
        raise ValueError(f"{path}: result format {body.get('format')!r}, expected {RESULT_FORMAT}")
    return body


def _matrix(value: Any, shape: tuple[int, ...], what: str) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != shape or not np.isfinite(arr).all():
        raise ValueError(f"{what}: expected a finite {shape} array")
    return arr


def _model(value: Any) -> dict | None:
    """A stored model choice: None, or a JSON object."""
    if value is None:
        return None
    if not isinstance(value, dict):
        raise TypeError(f"model must be a JSON object, got {type(value).__name__}")
    return dict(value)


def _optional_float(value: Any) -> float | None:
    """A saved number, or None when it was not saved."""
    return None if value is None else float(value)


def _pairs(value: Any) -> np.ndarray:
    return np.asarray(value, dtype=np.int64).reshape(-1, 2)


@dataclass
class StepResult:
    """What one step produced.

    Attributes
    ----------
    name : str
    transformation : ndarray of shape (4, 4)
        Source-to-target transformation after this step.
    fitness : float
        Share of (global-step or full-resolution) source points with a target point
        within ``distance``, as Open3D reports it.
    inlier_rmse : float
        RMS distance of those inliers.
    correspondence_set : ndarray of shape (m, 2)
        The step's inlier pairs ``(source index, target index)``; indices refer to the
        clouds the step worked on (global steps: the downsampled clouds).
    seconds : float
    info : dict
        Step-specific numbers (distances used, number of candidate matches, ...).
    distance : float
        The correspondence distance ``fitness`` and ``inlier_rmse`` were measured at.
    matches : ndarray of shape (m, 2, 3) or None
        Global steps that match descriptors: every match the step was given, as (source
        point, target point) in the caller's coordinates; ``None`` for other steps.
    match_inliers : ndarray of shape (m,) or None
        Which of ``matches`` the step's estimate explains (within ``distance``).
    """

    name: str
    transformation: np.ndarray
    fitness: float
    inlier_rmse: float
    correspondence_set: np.ndarray
    seconds: float = 0.0
    info: dict = field(default_factory=dict)
    distance: float = 0.0
    matches: np.ndarray | None = None
    match_inliers: np.ndarray | None = None

    def as_dict(self) -> dict:
        return {
            "name": self.name,
            "transformation": self.transformation.tolist(),
            "fitness": self.fitness,
            "inlier_rmse": self.inlier_rmse,
            "n_correspondences": int(len(self.correspondence_set)),
            "seconds": self.seconds,
            "distance": self.distance,
            "info": self.info,
        }

    def _full(self) -> dict:
        return {
            **self.as_dict(),
            "correspondence_set": self.correspondence_set,
            "matches": self.matches,
            "match_inliers": self.match_inliers,
        }

    @classmethod
    def _from_full(cls, body: dict) -> StepResult:
        return cls(
            name=str(body["name"]),
            transformation=_matrix(body["transformation"], (4, 4), "step transformation"),
            fitness=float(body["fitness"]),
            inlier_rmse=float(body["inlier_rmse"]),
            correspondence_set=_pairs(body["correspondence_set"]),
            seconds=float(body["seconds"]),
            info=dict(body["info"]),
            distance=float(body["distance"]),
            matches=None
            if body.get("matches") is None
            else np.asarray(body["matches"], dtype=np.float64).reshape(-1, 2, 3),
            match_inliers=None
            if body.get("match_inliers") is None
            else np.asarray(body["match_inliers"], dtype=bool),
        )

    @classmethod
    def from_open3d(
        cls, name: str, result, seconds: float, info: dict, distance: float
    ) -> StepResult:
        """A step result from Open3D's ``RegistrationResult``."""
        return cls(
            name=name,
            transformation=np.array(result.transformation),
            fitness=float(result.fitness),
            inlier_rmse=float(result.inlier_rmse),
            correspondence_set=np.asarray(result.correspondence_set, dtype=np.int64).reshape(-1, 2),
            seconds=seconds,
            info=info,
            distance=float(distance),
        )


@dataclass
class RegistrationResult:
    """The outcome of a registration.

    Attributes
    ----------
    transformation : ndarray of shape (4, 4)
        Maps source points into the target frame: ``target ~ source @ R.T + t``, as in
        Open3D.
    fitness : float
        Open3D's fitness: the share of the (full-resolution) source points that have a
        target point within ``distance`` (the last step's correspondence distance)
        after the transformation. The last step reports the same number when it ran on
        the full clouds; every step's own numbers are in ``steps``.
    inlier_rmse : float
        RMS distance of those inliers.
    correspondence_set : ndarray of shape (m, 2)
        Those inlier pairs ``(source index, target index)``, as in Open3D.
    steps : list of StepResult
        Every step's transformation, fitness, inliers and timing, in order.
    voxel_size : float
        The resolution the thresholds were derived from.
    seconds : float
        Wall time of the whole registration.
    preparation_seconds : float
        Of ``seconds``, the time spent preparing the clouds before the first step:
        downsampling them for the global step and describing them.
    distance : float
        The correspondence distance ``fitness`` was measured at.
    converged : bool
        False when fewer than 2 % of the source points found a partner (``fitness <
        0.02``), or when, measured within three times the resolution, the partners' RMS
        distance exceeds 0.47 of it: distances spread over the whole threshold are the
        mark of a chance alignment. Measured on training data: unrelated objects
        registered to each other 0.53-0.58; true poses of two different samples of an
        object, whole or cropped, 0.24-0.40. Wrong poses that align a scene's floors and
        walls can fit like right ones and are not always caught: the flag says "surely
        unreliable", not "surely right".
    ambiguous : bool
        True when the result turned by 180 degrees about one of the aligned source's
        principal axes fits about as well (fitness within three resolutions at least
        90 % of the result's, on the global clouds; the twins are not refined, so they
        are judged at that wider distance): a symmetric shape, or a featureless plane,
        whose pose the data cannot decide. A :class:`RegistrationWarning` is issued
        with either flag.
    model : dict or None
        What ``register(descriptor="auto")`` chose (``ModelChoice.as_dict()``: the
        shipped model, the viewpoints and why); None for a given descriptor.
    """

    transformation: np.ndarray
    fitness: float
    inlier_rmse: float
    correspondence_set: np.ndarray
    steps: list[StepResult] = field(default_factory=list)
    voxel_size: float = 0.0
    seconds: float = 0.0
    distance: float = 0.0
    converged: bool = True
    ambiguous: bool = False
    preparation_seconds: float = 0.0
    model: dict | None = None

    @property
    def margin(self) -> float | None:
        """How far the global step's chosen hypothesis scored above its best distinct
        rival (``1 - rival / chosen``; 1 when no rival was distinct, below 0 when a
        rival scored higher without beating the step's own choice by enough to replace
        it), when it verified several (``n_hypotheses``); None when it did not."""
        margins = [s.info["margin"] for s in self.steps if "margin" in s.info]
        return min(margins) if margins else None

    @property
    def support(self) -> float | None:
        """The share of the global step's descriptor matches that its estimate explains
        (``match_inliers``: within the step's inlier distance), from 0 to 1; None
        without a global step that matched descriptors.

        Few agreeing matches mark a pose the matches barely single out: at low overlap
        the results with little support are the ones most often wrong while flagged as
        neither unconverged nor ambiguous (docs/registration.md, "How far to trust a
        result"). The share is of the matches the step was given, so it compares
        results of one descriptor and step setting, not across them."""
        for step in self.steps:
            if step.match_inliers is not None and len(step.match_inliers):
                return float(np.mean(step.match_inliers))
        return None

    def to_open3d(self):
        """This result as an ``open3d.pipelines.registration.RegistrationResult``
        (transformation, fitness, inlier RMSE and correspondence set)."""
        import open3d as o3d

        out = o3d.pipelines.registration.RegistrationResult()
        out.transformation = np.asarray(self.transformation, dtype=np.float64)
        out.fitness = float(self.fitness)
        out.inlier_rmse = float(self.inlier_rmse)
        out.correspondence_set = o3d.utility.Vector2iVector(
            np.asarray(self.correspondence_set, dtype=np.int32).reshape(-1, 2)
        )
        return out

    @classmethod
    def from_quality(
        cls,
        quality: Any,
        transformation: np.ndarray,
        steps: list[StepResult],
        *,
        voxel_size: float,
        seconds: float,
        distance: float,
        preparation_seconds: float = 0.0,
    ) -> RegistrationResult:
        """A result from the measurements behind its flags (``flags.Quality``): its
        fitness, inlier RMSE and inlier pairs are ``quality.final``'s, its flags
        ``quality``'s. What ``register()`` and :func:`~o3d_rpointhop.evaluate` both
        return."""
        return cls(
            transformation=transformation,
            fitness=quality.final.fitness,
            inlier_rmse=quality.final.inlier_rmse,
            correspondence_set=quality.final.correspondence_set,
            steps=steps,
            voxel_size=voxel_size,
            seconds=seconds,
            distance=distance,
            converged=quality.converged,
            ambiguous=quality.ambiguous,
            preparation_seconds=preparation_seconds,
        )

    def as_dict(self) -> dict:
        """JSON-ready summary (the CLI's ``--json`` output)."""
        return {
            "transformation": self.transformation.tolist(),
            "fitness": self.fitness,
            "inlier_rmse": self.inlier_rmse,
            "n_correspondences": int(len(self.correspondence_set)),
            "voxel_size": self.voxel_size,
            "distance": self.distance,
            "converged": self.converged,
            "ambiguous": self.ambiguous,
            "support": self.support,
            "margin": self.margin,
            "seconds": self.seconds,
            "preparation_seconds": self.preparation_seconds,
            "model": self.model,
            "steps": [s.as_dict() for s in self.steps],
        }

    def save(self, path: str | os.PathLike, provenance: dict | None = None) -> None:
        """Write everything this result holds (inlier pairs and every step included) to
        a JSON file that :meth:`load` reads back; ``provenance``, a JSON-ready record of
        what made it (the command line's: version, commit, descriptor, config), is
        stored beside it under ``"provenance"``."""
        body = {
            **self.as_dict(),
            "correspondence_set": self.correspondence_set,
            "steps": [s._full() for s in self.steps],
        }
        write_json(path, "RegistrationResult", body, provenance)

    @classmethod
    def load(cls, path: str | os.PathLike) -> RegistrationResult:
        """A result :meth:`save` wrote; ValueError for any other file."""
        body = read_json(path, "RegistrationResult")
        try:
            return cls(
                transformation=_matrix(body["transformation"], (4, 4), f"{path}"),
                fitness=float(body["fitness"]),
                inlier_rmse=float(body["inlier_rmse"]),
                correspondence_set=_pairs(body["correspondence_set"]),
                steps=[StepResult._from_full(step) for step in body["steps"]],
                voxel_size=float(body["voxel_size"]),
                seconds=float(body["seconds"]),
                distance=float(body["distance"]),
                converged=bool(body["converged"]),
                ambiguous=bool(body["ambiguous"]),
                preparation_seconds=float(body.get("preparation_seconds", 0.0)),  # older files
                model=_model(body.get("model")),
            )
        except (KeyError, TypeError) as exc:
            raise ValueError(f"{path}: a damaged saved result ({exc!r})") from None


#: Colours of the scans in a merged cloud, in scan order (matplotlib's "tab10").
SCAN_COLOURS = np.array(
    [
        [0.12, 0.47, 0.71],
        [1.0, 0.5, 0.05],
        [0.17, 0.63, 0.17],
        [0.84, 0.15, 0.16],
        [0.58, 0.4, 0.74],
        [0.55, 0.34, 0.29],
        [0.89, 0.47, 0.76],
        [0.5, 0.5, 0.5],
        [0.74, 0.74, 0.13],
        [0.09, 0.75, 0.81],
    ]
)
#: The colour of the points of scans without colours merged with scans that have them.
UNCOLOURED = (0.5, 0.5, 0.5)


@dataclass
class MultiwayResult:
    """The outcome of :func:`register_multiway`.

    Attributes
    ----------
    poses : list of (ndarray of shape (4, 4) or None)
        ``poses[k]`` maps scan ``k`` into scan ``frame``'s frame; ``None`` for a scan
        outside the placed part.
    pose_graph : open3d.pipelines.registration.PoseGraph
        The optimised graph (nodes: the placed scans in order; edges: kept pairs).
    pairs : dict
        ``(i, j) -> (transformation, fitness)`` for every candidate pair registered
        (the transformation maps scan ``j`` into scan ``i``).
    edges : list of tuple
        The pairs kept after optimisation, ``(i, j)``.
    unconnected : list of int
        Scans outside the placed part (left out, never placed silently).
    voxel_size : float
        The common resolution.
    seconds : float
    frame : int
        The scan whose frame the poses are in: scan 0 when it is placed, else the
        placed scan given first.
    parts : list of list of int
        The parts the screened pairs join the scans into, each its scans in order: the
        placed one first (the most scans, then the most total edge fitness), then the
        others from the largest down (a scan no pair joins is a part of its own).
    part_poses : list of list
        One reconstruction per part, in the order of ``parts``: ``part_poses[p][k]``
        maps scan ``k`` into the frame of part ``p``'s scan given first (None outside
        the part). Each smaller part is reconstructed as the placed one is (optimised,
        refined on the full scans), on its own; ``part_poses[0]`` is ``poses``.
    model : dict or None
        The automatic model choice (``ModelChoice.as_dict()``: the model, the
        viewpoints and why), None for a given descriptor.
    free_space : dict
        ``(i, j) -> share`` for every pair that fit (edge fitness at least
        ``min_fitness``) when the sensors were known: the share of either scan its pose
        put in space the other's sensor saw empty; pairs above ``max_violation`` were
        left out of the graph. Empty without sensor positions.
    min_fitness, max_violation : float or None
        The thresholds the pairs were screened with (None when not known: a result
        saved before they were kept); :meth:`left_out` explains with them.
    """

    poses: list
    pose_graph: Any
    pairs: dict = field(default_factory=dict)
    edges: list = field(default_factory=list)
    unconnected: list = field(default_factory=list)
    voxel_size: float = 0.0
    seconds: float = 0.0
    frame: int = 0
    parts: list = field(default_factory=list)
    part_poses: list = field(default_factory=list)
    model: dict | None = None
    free_space: dict = field(default_factory=dict)
    min_fitness: float | None = None
    max_violation: float | None = None

    def left_out(self, names: list[str] | None = None) -> dict[int, str]:
        """Why each scan of :attr:`unconnected` was not placed, in words.

        A scan is left out when it lies in a smaller part than the placed one (its pairs
        join it only to scans outside the placed part), when none of its pairs fit (edge
        fitness below ``min_fitness``), when the pairs that fit put too much of a scan
        where the other's sensor saw empty space (``max_violation``), or when its edges
        did not survive the pose graph's optimisation.

        Parameters
        ----------
        names : list of str, default=None
            What to call the scans (default: ``"scan k"``).

        Returns
        -------
        dict
            ``{scan index: reason}`` for every unconnected scan.
        """
        names = names or [f"scan {k}" for k in range(len(self.poses))]
        placed = (
            self.parts[0] if self.parts else [k for k, p in enumerate(self.poses) if p is not None]
        )
        floor = 0.0 if self.min_fitness is None else self.min_fitness
        limit = 1.0 if self.max_violation is None else self.max_violation
        reasons = {}
        for k in self.unconnected:
            part = next((p for p in self.parts if k in p), [k])
            own = {pair: f for pair, (_, f) in self.pairs.items() if k in pair}
            fit = {pair: f for pair, f in own.items() if f >= floor}
            seen = {pair: self.free_space[pair] for pair in fit if pair in self.free_space}
            if len(part) > 1 and k not in placed:
                others = ", ".join(names[j] for j in part if j != k)
                reasons[k] = (
                    f"in a smaller part ({len(part)} scans, with {others}) than the placed "
                    f"one ({len(placed)} scans): no pair that fit joins them"
                )
            elif not own:
                reasons[k] = "paired with no scan"
            elif not fit:
                (i, j), best = max(own.items(), key=lambda item: item[1])
                reasons[k] = (
                    f"no pair fit: the best, with {names[j if i == k else i]}, has edge "
                    f"fitness {best:.2f} (at least {floor:.2f} needed)"
                )
            elif seen and all(share > limit for share in seen.values()) and len(seen) == len(fit):
                (i, j), share = min(seen.items(), key=lambda item: item[1])
                reasons[k] = (
                    f"every pair that fit puts too much of a scan where the other sensor saw "
                    f"empty space: the least, with {names[j if i == k else i]}, "
                    f"{share:.0%} (at most {limit:.0%})"
                )
            else:
                reasons[k] = (
                    "its edges were dropped from the pose graph: their poses disagree with "
                    "the rest of the placed part"
                )
        return reasons

    def unverified(self, names: list[str] | None = None) -> dict[int, str]:
        """The placed scans joined to the rest of the reconstruction by edges no loop
        of the pose graph checks, each with those edges, in words.

        An edge inside a loop of kept edges is checked by the loop's other edges (the
        optimisation weighs them against each other); a bridge, an edge no loop
        contains, is not: if its pose is wrong, the scans on one side are placed wrong
        against those on the other and nothing in the graph can tell. Each bridge
        names the scans on its smaller side (of two alike, the one whose kept edges sum
        to less fitness; then the side without the frame's scan). The scans are placed
        all the same (and ``reconstruct`` exits 0 for them); this says which placements
        rest on one pair's word. On the scene model's training and held-out rooms every
        wrongly placed group was the smaller side of such an edge, and most such edges
        were right (docs/multiway.md, "Placements no loop checks").

        Parameters
        ----------
        names : list of str, default=None
            What to call the scans (default: ``"scan k"``).

        Returns
        -------
        dict
            ``{scan index: reason}`` for every placed scan on the smaller side of a
            bridge, its bridges listed from the larger sides to the smaller.
        """
        from .pose_graph import bridges

        names = names or [f"scan {k}" for k in range(len(self.poses))]
        placed = {k for k, pose in enumerate(self.poses) if pose is not None}

        def support(side: list[int]) -> float:
            inside = set(side)
            return sum(
                self.pairs.get(tuple(e), (None, 0.0))[1] for e in self.edges if set(e) <= inside
            )

        sides = []
        for (i, j), far in bridges([tuple(e) for e in self.edges], self.frame):
            near = sorted(placed - set(far))
            # The smaller side; of two alike, the one its kept edges support less, so
            # that the order the scans came in decides only a tie of both.
            key_far, key_near = (len(far), support(far)), (len(near), support(near))
            sides.append(((i, j), far if key_far <= key_near else near))
        # The larger cut-off sides first: the bridges nearest the rest of the room.
        sides.sort(key=lambda b: (-len(b[1]), b[0]))
        behind: dict[int, list[str]] = {}
        for (i, j), side in sides:
            fitness = self.pairs[(i, j)][1] if (i, j) in self.pairs else float("nan")
            words = f"{names[i]} - {names[j]} (edge fitness {fitness:.2f})"
            for k in side:
                behind.setdefault(k, []).append(words)
        return {
            k: (
                f"joined to the other scans through {len(edges)} edge"
                f"{'s' if len(edges) > 1 else ''} that no loop of the pose graph checks: "
                + ", then ".join(edges)
            )
            for k, edges in sorted(behind.items())
        }

    def merge(
        self,
        clouds: list[Any],
        *,
        voxel_size: float | str | None = "auto",
        colour: bool = True,
    ) -> o3d.geometry.PointCloud:
        """The placed scans in scan ``frame``'s frame as one cloud.

        Parameters
        ----------
        clouds : list of array-like (n_k, 3) or Open3D point clouds
            The scans given to :func:`register_multiway`, in the same order.
        voxel_size : float, "auto" or None, default="auto"
            Voxel the merged cloud is downsampled to; ``"auto"`` is half the common
            resolution, ``None`` keeps every point.
        colour : bool, default=True
            Paint each scan in its own colour (:data:`SCAN_COLOURS`, in scan order);
            ``False`` keeps the scans' own colours and normals (turned with them); when
            only some scans have colours, the others' points are grey
            (:data:`UNCOLOURED`), with a warning.

        Returns
        -------
        open3d.geometry.PointCloud
            Unconnected scans are left out.
        """
        if len(clouds) != len(self.poses):
            raise ValueError(f"{len(self.poses)} scans were registered, got {len(clouds)}")
        parts = {}
        for k, (scan, pose) in enumerate(zip(clouds, self.poses, strict=True)):
            if pose is None:
                continue
            part = o3d.geometry.PointCloud(to_point_cloud(scan, f"clouds[{k}]"))
            part.transform(pose)  # turns the normals too
            if colour:
                part.paint_uniform_color(SCAN_COLOURS[k % len(SCAN_COLOURS)])
            parts[k] = part
        # A cloud has colours on every point or on none: when only some scans have
        # them, the others are filled with grey rather than every colour dropped.
        bare = [k for k, part in parts.items() if not part.has_colors()]
        if bare and len(bare) < len(parts):
            for k in bare:
                parts[k].paint_uniform_color(UNCOLOURED)
            warnings.warn(
                f"scans {bare} have no colours: their points are grey "
                f"{list(UNCOLOURED)} in the merged cloud",
                UserWarning,
                stacklevel=2,
            )
        merged = o3d.geometry.PointCloud()
        for part in parts.values():
            merged += part
        if voxel_size is None:
            return merged
        return merged.voxel_down_sample(
            self.voxel_size / 2 if isinstance(voxel_size, str) else float(voxel_size)
        )

    def mesh(
        self, clouds: list[Any], *, voxel_size: float | None = None, depth: int = 9
    ) -> o3d.geometry.TriangleMesh:
        """A surface through the merged scans: Open3D's screened Poisson reconstruction.

        Normals are estimated within 4 voxels of the merged cloud and oriented
        consistently over their tangent planes before meshing.

        Parameters
        ----------
        clouds : list
            As in :meth:`merge`.
        voxel_size : float, default=None
            Voxel the scans are merged at before meshing; ``None`` is half the common
            resolution.
        depth : int, default=9
            Octree depth of the Poisson solver (detail, and memory).

        Returns
        -------
        open3d.geometry.TriangleMesh
        """
        voxel = voxel_size or self.voxel_size / 2
        merged = self.merge(clouds, voxel_size=voxel, colour=False)
        # Meshed about the merged cloud's centre: Qhull (in the normals' orientation)
        # and the Poisson solver lose precision at survey coordinates.
        centre = merged.get_center()
        merged.translate(-centre)
        merged.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=4 * voxel, max_nn=30))
        merged.orient_normals_consistent_tangent_plane(16)
        mesh, _ = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(merged, depth=depth)
        return mesh.translate(centre)

    def save(self, path: str | os.PathLike, provenance: dict | None = None) -> None:
        """Write the poses, the candidate pairs, the edges and the optimised pose graph
        (nodes, edges with their information matrices) to a JSON file that
        :meth:`load` reads back. (``o3d-rpointhop reconstruct --pose-graph`` writes the
        graph alone in Open3D's format, for ``open3d.io.read_pose_graph``.)
        ``provenance``: as :meth:`RegistrationResult.save` stores it."""
        graph = self.pose_graph
        body = {
            "poses": self.poses,
            "pairs": [[i, j, t, f] for (i, j), (t, f) in sorted(self.pairs.items())],
            "edges": [list(e) for e in self.edges],
            "unconnected": list(self.unconnected),
            "voxel_size": self.voxel_size,
            "seconds": self.seconds,
            "frame": self.frame,
            "parts": [list(part) for part in self.parts],
            "part_poses": self.part_poses,
            "model": self.model,
            "free_space": [[i, j, share] for (i, j), share in sorted(self.free_space.items())],
            "min_fitness": self.min_fitness,
            "max_violation": self.max_violation,
            "pose_graph": {
                "nodes": [np.asarray(n.pose) for n in graph.nodes],
                "edges": [
                    {
                        "source": int(e.source_node_id),
                        "target": int(e.target_node_id),
                        "transformation": np.asarray(e.transformation),
                        "information": np.asarray(e.information),
                        "uncertain": bool(e.uncertain),
                        "confidence": float(e.confidence),
                    }
                    for e in graph.edges
                ],
            },
        }
        write_json(path, "MultiwayResult", body, provenance)

    @classmethod
    def load(cls, path: str | os.PathLike) -> MultiwayResult:
        """A result :meth:`save` wrote; ValueError for any other file."""
        body = read_json(path, "MultiwayResult")
        try:
            graph = reg.PoseGraph()
            for pose in body["pose_graph"]["nodes"]:
                graph.nodes.append(reg.PoseGraphNode(_matrix(pose, (4, 4), f"{path}")))
            for e in body["pose_graph"]["edges"]:
                edge = reg.PoseGraphEdge(
                    int(e["source"]),
                    int(e["target"]),
                    _matrix(e["transformation"], (4, 4), f"{path}"),
                    _matrix(e["information"], (6, 6), f"{path}"),
                    uncertain=bool(e["uncertain"]),
                    confidence=float(e["confidence"]),
                )
                graph.edges.append(edge)
            return cls(
                poses=[None if p is None else _matrix(p, (4, 4), f"{path}") for p in body["poses"]],
                pose_graph=graph,
                pairs={
                    (int(i), int(j)): (_matrix(t, (4, 4), f"{path}"), float(f))
                    for i, j, t, f in body["pairs"]
                },
                edges=[tuple(int(v) for v in e) for e in body["edges"]],
                unconnected=[int(k) for k in body["unconnected"]],
                voxel_size=float(body["voxel_size"]),
                seconds=float(body["seconds"]),
                frame=int(body.get("frame", 0)),
                parts=[[int(k) for k in part] for part in body.get("parts", [])],
                part_poses=[
                    [None if p is None else _matrix(p, (4, 4), f"{path}") for p in part]
                    for part in body.get("part_poses", [])
                ],
                model=_model(body.get("model")),
                free_space={
                    (int(i), int(j)): float(share) for i, j, share in body.get("free_space", [])
                },
                min_fitness=_optional_float(body.get("min_fitness")),
                max_violation=_optional_float(body.get("max_violation")),
            )
        except (KeyError, TypeError) as exc:
            raise ValueError(f"{path}: a damaged saved result ({exc!r})") from None

    def as_dict(self, names: list[str] | None = None) -> dict:
        """JSON-ready poses, edges and flags, scans called by ``names`` (default: their
        indices)."""
        names = names or [str(k) for k in range(len(self.poses))]
        return {
            "scans": list(names),
            "poses": [None if p is None else p.tolist() for p in self.poses],
            "unconnected": [names[k] for k in self.unconnected],
            "left_out": {names[k]: why for k, why in self.left_out(names).items()},
            "unverified": {names[k]: why for k, why in self.unverified(names).items()},
            "frame": names[self.frame],
            "parts": [[names[k] for k in part] for part in self.parts],
            "edges": [[names[i], names[j]] for i, j in self.edges],
            "voxel_size": self.voxel_size,
            "seconds": self.seconds,
            "model": self.model,
        }
