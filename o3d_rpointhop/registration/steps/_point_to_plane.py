"""Point-to-plane ICP, compiled: many trial poses of one pair, or one pose on every core.

Each iteration is Open3D's point-to-plane step: correspondences to the nearest target
point within the distance (from the target's
:class:`~o3d_rpointhop._utils.cells.CellGrid`, as wide as the correspondence distance,
built once), the linearised residual ``(R p + t - q) . n_q`` solved for a small rotation
(Z-Y-X angles) and translation, the update applied on the left; it stops after
``max_iteration`` or when fitness and inlier RMSE change less than the relative
criteria (Open3D's defaults: 1e-6).

- :func:`refine_point_to_plane`: verifying hypotheses refines a few poses of the same
  pair before scoring them; Open3D's ICP builds its target's k-d tree and threads on
  every call, which costs more than the few iterations on a few thousand points do.
  Every pose is refined in one compiled call, the poses shared out over threads.
- :func:`point_to_plane_icp`: the ICP steps' passes. Open3D's ``registration_icp``
  runs on one thread here (``repeatable_open3d``: with more it sums its residuals in an
  order set by thread timing) and searches a k-d tree per point and iteration; on a
  25k-point 3DMatch fragment its 50 iterations took 0.75 s on one thread, these 0.15 s,
  to the same correspondences and the pose within 1e-15. The source is cut into blocks
  of :data:`BLOCK` points whose equations are summed alone, on any thread, then added
  in block order, so the pose does not depend on the thread count.

Fewer than six correspondences, or ones that cannot fix all six motions (the normal
equations not positive definite), end a pass where Open3D's LDLT still solves the
singular system for some motion: an ICP from a far start that finds almost nothing can
end elsewhere than Open3D's (both unconverged).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..._utils.cells import CellGrid, nearest_one
from ..._utils.compiled import kernel
from ..._utils.threads import map_threads, run_blocks

__all__ = ["BLOCK", "PlaneICPResult", "point_to_plane_icp", "refine_point_to_plane"]

#: Open3D's default convergence criteria (``ICPConvergenceCriteria``).
RELATIVE_FITNESS = 1e-6
RELATIVE_RMSE = 1e-6


@kernel(inline="always")
def _normal_equations(
    source, transformation, points, starts, lo, inv_cell, dims, sq_radius, normals, ata, atb
):  # pragma: no cover - compiled
    """Fill ``ata`` (6, 6) and ``atb`` (6,) with the point-to-plane normal equations at
    ``transformation``; return the correspondences' count and the sum of their squared
    (point-to-point) distances."""
    ata[:] = 0.0
    atb[:] = 0.0
    count = 0
    squares = 0.0
    r = transformation
    for i in range(source.shape[0]):
        x, y, z = source[i, 0], source[i, 1], source[i, 2]
        px = r[0, 0] * x + r[0, 1] * y + r[0, 2] * z + r[0, 3]
        py = r[1, 0] * x + r[1, 1] * y + r[1, 2] * z + r[1, 3]
        pz = r[2, 0] * x + r[2, 1] * y + r[2, 2] * z + r[2, 3]
        best, j = nearest_one(px, py, pz, points, starts, lo, inv_cell, dims, sq_radius)
        if j < 0:
            continue
        nx, ny, nz = normals[j, 0], normals[j, 1], normals[j, 2]
        res = (px - points[j, 0]) * nx + (py - points[j, 1]) * ny + (pz - points[j, 2]) * nz
        jac = (py * nz - pz * ny, pz * nx - px * nz, px * ny - py * nx, nx, ny, nz)
        for a in range(6):
            atb[a] += jac[a] * res
            for b in range(a, 6):
                ata[a, b] += jac[a] * jac[b]
        count += 1
        squares += best
    for a in range(6):
        for b in range(a):
            ata[a, b] = ata[b, a]
    return count, squares


@kernel(inline="always")
def _solve_6(ata, atb, x):  # pragma: no cover - compiled
    """``x = -ata^-1 atb`` by Cholesky; False when ``ata`` is not positive definite
    (too few or degenerate correspondences)."""
    low = np.zeros((6, 6))
    for i in range(6):
        for j in range(i + 1):
            s = ata[i, j]
            for k in range(j):
                s -= low[i, k] * low[j, k]
            if i == j:
                if s <= 1e-12 * (1.0 + abs(ata[i, i])):
                    return False
                low[i, i] = np.sqrt(s)
            else:
                low[i, j] = s / low[j, j]
    y = np.zeros(6)
    for i in range(6):
        s = -atb[i]
        for k in range(i):
            s -= low[i, k] * y[k]
        y[i] = s / low[i, i]
    for i in range(5, -1, -1):
        s = y[i]
        for k in range(i + 1, 6):
            s -= low[k, i] * x[k]
        x[i] = s / low[i, i]
    return True


@kernel(inline="always")
def _update(x):  # pragma: no cover - compiled
    """The 4x4 motion of the small-step vector ``x``: rotation Rz(x2) Ry(x1) Rx(x0)
    (Open3D's ``TransformVector6dToMatrix4d``), translation ``x[3:]``."""
    ca, sa = np.cos(x[0]), np.sin(x[0])
    cb, sb = np.cos(x[1]), np.sin(x[1])
    cg, sg = np.cos(x[2]), np.sin(x[2])
    out = np.eye(4)
    out[0, 0] = cg * cb
    out[0, 1] = cg * sb * sa - sg * ca
    out[0, 2] = cg * sb * ca + sg * sa
    out[1, 0] = sg * cb
    out[1, 1] = sg * sb * sa + cg * ca
    out[1, 2] = sg * sb * ca - cg * sa
    out[2, 0] = -sb
    out[2, 1] = cb * sa
    out[2, 2] = cb * ca
    out[0, 3], out[1, 3], out[2, 3] = x[3], x[4], x[5]
    return out


@kernel(nogil=True)
def _refine_all(
    source,
    hypotheses,
    points,
    starts,
    lo,
    inv_cell,
    dims,
    sq_radius,
    normals,
    max_iteration,
    relative_fitness,
    relative_rmse,
):  # pragma: no cover - compiled
    """Every hypothesis refined by point-to-plane ICP (see the module)."""
    out = hypotheses.copy()
    ata = np.zeros((6, 6))
    atb = np.zeros(6)
    x = np.zeros(6)
    n = source.shape[0]
    for h in range(hypotheses.shape[0]):
        current = hypotheses[h].copy()
        count, squares = _normal_equations(
            source, current, points, starts, lo, inv_cell, dims, sq_radius, normals, ata, atb
        )
        for _ in range(max_iteration):
            if count < 6 or not _solve_6(ata, atb, x):
                break
            current = _update(x) @ current
            fitness, rmse = count / n, np.sqrt(squares / count)
            count, squares = _normal_equations(
                source, current, points, starts, lo, inv_cell, dims, sq_radius, normals, ata, atb
            )
            rmse_now = np.sqrt(squares / count) if count else 0.0
            if abs(count / n - fitness) < relative_fitness and abs(rmse_now - rmse) < relative_rmse:
                break
        out[h] = current
    return out


def refine_point_to_plane(
    source: np.ndarray,
    grid: CellGrid,
    target_normals: np.ndarray,
    hypotheses: np.ndarray,
    max_iteration: int,
    n_threads: int = 1,
) -> np.ndarray:
    """Refine every pose of ``hypotheses`` (k, 4, 4) of ``source`` (n, 3) onto the
    target behind ``grid`` (a :class:`CellGrid` of the target points, its radius the
    correspondence distance, :attr:`~CellGrid.on_cells`) with the target's unit
    ``target_normals`` (in the target's row order), by at most ``max_iteration``
    point-to-plane ICP iterations each. A pose with fewer than six correspondences, or
    whose correspondences cannot fix all six motions, stays as it is. The poses are
    shared out over ``n_threads`` threads; each is refined alone, so the result does
    not depend on the thread count."""
    normals = np.ascontiguousarray(target_normals[grid.order], dtype=np.float64)
    source = np.ascontiguousarray(source, dtype=np.float64)
    hypotheses = np.ascontiguousarray(hypotheses, dtype=np.float64)
    refined = np.empty_like(hypotheses)
    arguments = grid.kernel_arguments()

    def refine(start: int, stop: int) -> None:
        refined[start:stop] = _refine_all(
            source,
            hypotheses[start:stop],
            *arguments,
            normals,
            int(max_iteration),
            RELATIVE_FITNESS,
            RELATIVE_RMSE,
        )

    run_blocks(refine, len(hypotheses), n_threads)
    return refined


#: Source points per block of the normal equations: the unit of work of a thread and
#: of the summation order.
BLOCK = 4096


@dataclass
class PlaneICPResult:
    """What :func:`point_to_plane_icp` found, as Open3D's ``RegistrationResult`` holds it:
    the pose, the share of source points with a target point within the distance, the
    RMSE of those distances and the pairs ``(source row, target row)``."""

    transformation: np.ndarray
    fitness: float
    inlier_rmse: float
    correspondence_set: np.ndarray


@kernel(nogil=True)
def _block_equations(
    source,
    start,
    stop,
    transformation,
    points,
    starts,
    lo,
    inv_cell,
    dims,
    sq_radius,
    normals,
    ata,
    atb,
    counts,
    squares,
    k,
):  # pragma: no cover - compiled
    """Block ``k`` (source rows ``start:stop``): its normal equations into ``ata[k]`` and
    ``atb[k]``, its correspondences' count and squared distances into ``counts[k]`` and
    ``squares[k]``."""
    count, sq = _normal_equations(
        source[start:stop],
        transformation,
        points,
        starts,
        lo,
        inv_cell,
        dims,
        sq_radius,
        normals,
        ata[k],
        atb[k],
    )
    counts[k] = count
    squares[k] = sq


@kernel()
def _step(ata, atb):  # pragma: no cover - compiled
    """The motion that solves the summed equations, and whether they could be solved."""
    x = np.zeros(6)
    if not _solve_6(ata, atb, x):
        return np.eye(4), False
    return _update(x), True


def point_to_plane_icp(
    source: np.ndarray,
    grid: CellGrid,
    target_normals: np.ndarray,
    init: np.ndarray,
    max_iteration: int,
    relative_fitness: float,
    relative_rmse: float,
    n_threads: int = 1,
) -> PlaneICPResult:
    """Refine ``init`` (4, 4) of ``source`` (n, 3) onto the target behind ``grid`` (a
    :class:`CellGrid` of the target points, :attr:`~CellGrid.on_cells`, its radius the
    correspondence distance) with the target's unit ``target_normals`` (target row
    order), by point-to-plane ICP. Fewer than six correspondences, or ones that cannot
    fix all six motions, end it. The result does not depend on ``n_threads``."""
    source = np.ascontiguousarray(source, dtype=np.float64)
    normals = np.ascontiguousarray(target_normals[grid.order], dtype=np.float64)
    arguments = grid.kernel_arguments()
    n = len(source)
    bounds = [(k, start, min(n, start + BLOCK)) for k, start in enumerate(range(0, n, BLOCK))]
    ata = np.zeros((len(bounds), 6, 6))
    atb = np.zeros((len(bounds), 6))
    counts = np.zeros(len(bounds), dtype=np.int64)
    squares = np.zeros(len(bounds))

    def equations(current: np.ndarray) -> tuple[int, float]:
        def block(k: int, start: int, stop: int) -> None:
            _block_equations(
                source, start, stop, current, *arguments, normals, ata, atb, counts, squares, k
            )

        map_threads(block, bounds, n_threads)
        return int(counts.sum()), float(_in_order(squares))

    current = np.ascontiguousarray(init, dtype=np.float64)
    count, squared = equations(current)
    for _ in range(int(max_iteration)):
        if count < 6:
            break
        update, solved = _step(_in_order(ata), _in_order(atb))
        if not solved:
            break
        current = update @ current
        fitness, rmse = count / n, np.sqrt(squared / count)
        count, squared = equations(current)
        rmse_now = np.sqrt(squared / count) if count else 0.0
        if abs(count / n - fitness) < relative_fitness and abs(rmse_now - rmse) < relative_rmse:
            break
    pairs, squared = grid.moved_pairs(source, current)
    kept = len(pairs)
    rmse = float(np.sqrt(squared.sum() / kept)) if kept else 0.0
    return PlaneICPResult(current, kept / n if n else 0.0, rmse, pairs)


def _in_order(parts: np.ndarray) -> np.ndarray:
    """The blocks' parts added one after another in block order (a fixed order whatever
    the threads)."""
    total = parts[0].copy()
    for part in parts[1:]:
        total += part
    return total
