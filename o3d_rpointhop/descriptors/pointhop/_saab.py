"""The Saab transform and its channel-wise form (R-PointHop paper, Appendix).

A Saab transform of ``d``-dimensional vectors has one DC kernel ``1 / sqrt(d)`` and
``d - 1`` AC kernels, the principal axes of the vectors with their DC part removed. The
channel-wise form applies an independent Saab transform to each channel; all channels
are handled at once as a batch of small matrices.

The bias. The paper adds to every output a bias ``b >= max ||v||`` so that outputs are
non-negative, which matters before a nonlinearity; R-PointHop has none. Octant pooling
is shift-equivariant (a constant added to a channel comes out unchanged in every octant
mean, empty octants included), so any per-output constant only moves every final
descriptor by one constant vector, which no distance, nearest-neighbour search or PCA
sees. We therefore subtract each output's training mean instead of adding ``b``: the
outputs are centred, and float32 features keep their full precision relative to their
spread rather than to a large offset.

Fitting only needs each channel's mean and covariance, which
:class:`MomentAccumulator` gathers from batches of samples, so fitting memory does not
grow with the number of training clouds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["MomentAccumulator", "SaabKernels", "fit_saab", "apply_saab"]


class MomentAccumulator:
    """Running per-channel mean and scatter matrix of sample vectors.

    Batches are merged with Chan et al.'s pairwise update, which stays accurate when the
    mean is large compared with the spread.

    Parameters
    ----------
    n_channels : int
    dim : int
    """

    def __init__(self, n_channels: int, dim: int) -> None:
        self.count = 0
        self.mean = np.zeros((n_channels, dim))
        self.scatter = np.zeros((n_channels, dim, dim))

    def update(self, samples: np.ndarray) -> None:
        """Add samples laid out channel-major, shape ``(n_channels, dim, n)``.

        The batch is centred on its own mean before its scatter matrix is formed, so the
        products can run in the samples' precision (float32 features) without losing
        the spread to cancellation; the running totals are float64.
        """
        n = samples.shape[2]
        if n == 0:
            return
        batch_mean = samples.mean(axis=2, dtype=np.float64)
        centred = samples - batch_mean[:, :, None].astype(samples.dtype)
        batch_scatter = np.matmul(centred, centred.transpose(0, 2, 1)).astype(np.float64)
        total = self.count + n
        delta = batch_mean - self.mean
        self.scatter += batch_scatter + delta[:, :, None] * delta[:, None, :] * (
            self.count * n / total
        )
        self.mean += delta * (n / total)
        self.count = total

    def covariance(self) -> np.ndarray:
        """Population covariance per channel, shape ``(n_channels, dim, dim)``."""
        if self.count == 0:
            raise ValueError("no samples were accumulated")
        return self.scatter / self.count


@dataclass
class SaabKernels:
    """Fitted Saab transforms for a batch of channels.

    Attributes
    ----------
    kernels : ndarray of shape (n_channels, dim, dim)
        Column 0 is the DC kernel, columns 1.. the AC kernels by decreasing variance.
    mean : ndarray of shape (n_channels, dim)
        Training mean of every output; :func:`apply_saab` subtracts it.
    energy : ndarray of shape (n_channels, dim)
        Share of each channel's variance carried by each output (rows sum to 1, or to 0
        for a channel without variance).
    """

    kernels: np.ndarray
    mean: np.ndarray
    energy: np.ndarray


def _dc_basis(dim: int) -> tuple[np.ndarray, np.ndarray]:
    """The DC kernel and an orthonormal basis of its complement, shape ``(dim, dim - 1)``."""
    dc = np.full(dim, 1.0 / np.sqrt(dim))
    projector = np.eye(dim) - np.outer(dc, dc)
    vals, vecs = np.linalg.eigh(projector)  # eigenvalues: one 0, then dim - 1 ones
    return dc, vecs[:, 1:]


def fit_saab(moments: MomentAccumulator) -> SaabKernels:
    """Fit one Saab transform per channel from accumulated moments."""
    cov = moments.covariance()
    n_channels, dim, _ = cov.shape
    dc, basis = _dc_basis(dim)
    cov_ac = np.einsum("ia,cij,jb->cab", basis, cov, basis)
    ac_var, ac_vecs = np.linalg.eigh(cov_ac)  # ascending
    ac_var = np.clip(ac_var[:, ::-1], 0.0, None)
    ac_kernels = np.einsum("ia,cab->cib", basis, ac_vecs[:, :, ::-1])
    # Fix each kernel's sign (its largest-magnitude weight positive) so that a refit on
    # the same data gives the same model on every platform.
    pivot = np.take_along_axis(ac_kernels, np.abs(ac_kernels).argmax(axis=1)[:, None, :], axis=1)
    ac_kernels *= np.where(pivot < 0, -1.0, 1.0)
    kernels = np.concatenate(
        [np.broadcast_to(dc[None, :, None], (n_channels, dim, 1)), ac_kernels], axis=2
    )
    dc_var = np.clip(np.einsum("i,cij,j->c", dc, cov, dc), 0.0, None)
    variances = np.concatenate([dc_var[:, None], ac_var], axis=1)
    total = variances.sum(axis=1, keepdims=True)
    energy = np.divide(variances, total, out=np.zeros_like(variances), where=total > 0)
    mean = np.einsum("cdj,cd->cj", kernels, moments.mean)
    return SaabKernels(kernels=kernels, mean=mean, energy=energy)


def apply_saab(samples: np.ndarray, kernels: np.ndarray, mean: np.ndarray) -> np.ndarray:
    """Transform channel-major samples ``(n_channels, dim, n)``; returns the same shape.

    ``out[c, j, i] = sum_d kernels[c, d, j] * samples[c, d, i] - mean[c, j]``, computed in
    the samples' precision. ``einsum`` sums every output in the
    same order wherever its sample sits, unlike a BLAS product, whose rounding depends on
    a column's position: reordering the points then reorders the result exactly.
    """
    dtype = samples.dtype
    # einsum runs 3x faster on a C-contiguous operand than on a transposed view.
    transposed = np.ascontiguousarray(kernels.transpose(0, 2, 1), dtype=dtype)
    out = np.einsum("ckd,cdi->cki", transposed, samples)
    out -= mean.astype(dtype)[:, :, None]
    return out
