"""The gradient term's image gradient ``D`` (docs/explanation/method.md §5): one implementation for both
sides of ``B D u ≈ ∇v``, the sources' ``∇v_k`` (:func:`vibr.geometry.compute_samples`) and
the target image's ``D u`` (:mod:`vibr.render.operators`, :mod:`vibr.render.fused`), with
one border rule. It lives in the geometry stage because the sources' gradients are computed
there (the renderer may import geometry, not the reverse).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .._runtime.jit import FASTMATH

__all__ = ["GRAD_SCHEMES", "DEFAULT_GRAD_SCHEME", "grad_image", "grad_image_adj"]


#: Discretisations of the gradient term's image gradient ``D`` (one list, docs/explanation/method.md §5):
#: ``"central"`` ½(u(j+1) − u(j−1)), replicated border (½ one-sided difference there);
#: ``"forward"`` u(j+1) − u(j), Neumann border (0 on the last column / row), whose
#: ``DᵀD`` is the compact 5-point Laplacian (the authors' ``Δ₄``, docs/explanation/method.md §10).
GRAD_SCHEMES = ("central", "forward")
#: The default (measured, docs/explanation/renderer.md "One image gradient").
DEFAULT_GRAD_SCHEME = "forward"


@njit(cache=True, fastmath=FASTMATH)
def _grad_row(u, k, forward, gx, gy):
    """Row k of ``D u`` for one channel ``u`` (H, W) into ``gx``, ``gy`` (W,): the one
    implementation of the gradient term's ``D``, used for the target image
    (:mod:`vibr.render.operators`, :mod:`vibr.render.fused`) and for the source images
    (:func:`vibr.geometry.compute_samples`)."""
    H, W = u.shape
    ur = u[k]
    if forward:
        for j in range(W - 1):
            gx[j] = ur[j + 1] - ur[j]
        gx[W - 1] = 0.0
        if k < H - 1:
            un = u[k + 1]
            for j in range(W):
                gy[j] = un[j] - ur[j]
        else:
            for j in range(W):
                gy[j] = 0.0
        return
    if W > 1:
        gx[0] = 0.5 * (ur[1] - ur[0])
        for j in range(1, W - 1):
            gx[j] = 0.5 * (ur[j + 1] - ur[j - 1])
        gx[W - 1] = 0.5 * (ur[W - 1] - ur[W - 2])
    else:
        gx[0] = 0.0
    a = u[min(k + 1, H - 1)]
    b = u[max(k - 1, 0)]
    for j in range(W):
        gy[j] = 0.5 * (a[j] - b[j])


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _grad_image(u, forward, g):
    C, H, W = u.shape
    for i in prange(H):
        for c in range(C):
            _grad_row(u[c], i, forward, g[c, 0, i], g[c, 1, i])
    return g


@njit(cache=True, fastmath=FASTMATH)
def _grad_adj_row(gx, gym, gyi, gyp, i, H, forward, o):
    """Row i of ``Dᵀ g`` into ``o`` (W,), from the row's x component ``gx`` and the y
    components of rows i−1, i, i+1 (``gym``, ``gyi``, ``gyp``; those outside are not read).
    Central, per axis: out[k] = ½(g[k-1]·[k≥1] + g[k]·[k=n-1]) − ½(g[k+1]·[k≤n-2] + g[k]·[k=0]);
    forward: out[k] = g[k-1]·[k≥1] − g[k]·[k≤n-2]."""
    W = o.shape[0]
    if forward:
        if W > 1:
            o[0] = -gx[0]
            for j in range(1, W - 1):
                o[j] = gx[j - 1] - gx[j]
            o[W - 1] = gx[W - 2]
        else:
            o[0] = 0.0
        if H > 1:
            if i >= 1:
                for j in range(W):
                    o[j] += gym[j]
            if i <= H - 2:
                for j in range(W):
                    o[j] -= gyi[j]
        return
    if W > 1:
        o[0] = -0.5 * (gx[1] + gx[0])
        for j in range(1, W - 1):
            o[j] = 0.5 * (gx[j - 1] - gx[j + 1])
        o[W - 1] = 0.5 * (gx[W - 2] + gx[W - 1])
    else:
        o[0] = 0.0
    if H > 1:
        if i >= 1:
            for j in range(W):
                o[j] += 0.5 * gym[j]
        if i == H - 1:
            for j in range(W):
                o[j] += 0.5 * gyi[j]
        if i <= H - 2:
            for j in range(W):
                o[j] -= 0.5 * gyp[j]
        if i == 0:
            for j in range(W):
                o[j] -= 0.5 * gyi[j]


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _grad_image_adj(g, forward, out):
    C, _, H, W = g.shape
    for i in prange(H):
        for c in range(C):
            _grad_adj_row(g[c, 0, i], g[c, 1, max(i - 1, 0)], g[c, 1, i], g[c, 1, min(i + 1, H - 1)],
                          i, H, forward, out[c, i])
    return out


def _is_forward(scheme) -> bool:
    if scheme not in GRAD_SCHEMES:
        raise ValueError(f"grad_scheme must be one of {GRAD_SCHEMES}, got {scheme!r}")
    return scheme == "forward"


def grad_image(u, scheme: str = "forward", out=None) -> np.ndarray:
    """The gradient term's image gradient ``D u`` (docs/explanation/method.md §5): (C, H, W) → (C, 2, H, W),
    ``[:, 0]`` = d/dx, ``[:, 1]`` = d/dy; ``scheme`` one of :data:`GRAD_SCHEMES`. The same
    operator gives the sources' ``∇v_k`` (one implementation, same border)."""
    fwd = _is_forward(scheme)
    if out is None:
        out = np.empty((u.shape[0], 2) + u.shape[1:], u.dtype)
    return _grad_image(u, fwd, out)


def grad_image_adj(g, scheme: str = "forward", out=None) -> np.ndarray:
    """Adjoint ``Dᵀ`` of :func:`grad_image`: (C, 2, H, W) → (C, H, W)."""
    fwd = _is_forward(scheme)
    if out is None:
        out = np.empty((g.shape[0],) + g.shape[2:], g.dtype)
    return _grad_image_adj(g, fwd, out)
