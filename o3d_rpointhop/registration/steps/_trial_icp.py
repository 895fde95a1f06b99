"""A short point-to-plane ICP for trying many starting poses on one pair, compiled.

Verifying hypotheses refines a few poses of the same pair before scoring them. Open3D's
ICP builds its target's k-d tree and threads on every call, which costs more than the
few iterations on a few thousand points do; here the target's cell grid
(:class:`~o3d_rpointhop._utils.cells.CellGrid`, as wide as the correspondence distance)
is built once and every pose refined in one compiled call. Each iteration is Open3D's
point-to-plane step: correspondences to the nearest target point within the distance,
the linearised residual ``(R p + t - q) . n_q`` solved for a small rotation (Z-Y-X
angles) and translation, the update applied on the left; it stops after
``max_iteration`` or when fitness and inlier RMSE change less than Open3D's default
relative criteria (1e-6).
"""

from __future__ import annotations

import numpy as np

from ..._utils.cells import CellGrid, nearest_one
from ..._utils.compiled import kernel
from ..._utils.threads import run_blocks

__all__ = ["refine_point_to_plane"]

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
