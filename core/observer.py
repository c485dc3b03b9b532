"""Initial ray momenta in the observer's local orthonormal frame (DESIGN.md "Observer").

For a spacetime the observer is the zero-angular-momentum observer u ∝ ξ_t + ω ξ_φ
(ω = −g(ξ_t, ξ_φ)/g(ξ_φ, ξ_φ)); without frame dragging that is the static observer.
Its spatial triad is the symmetric (Löwdin) orthonormalisation of the coordinate
images of the local Cartesian axes, so in flat space the frame is exactly the world's
axes and the rays are exactly Blender's. A photon *seen* along direction d arrives with
k = u − d; we trace it backwards, i.e. forwards with p = g(−u + d) (H is even in p).
"""

from __future__ import annotations

import numpy as np


class InsideHorizonError(ValueError):
    """No static or zero-angular-momentum observer exists where the camera is."""


def inverse_metric_soa(model, Q: np.ndarray) -> np.ndarray:
    """g^{ij}(q) as (N, n, n), read off a Hamiltonian quadratic in p: dH/dp_i at p = e_j."""
    n, n_rays = Q.shape
    ginv = np.empty((n_rays, n, n))
    for j in range(n):
        unit = np.zeros((n, n_rays))
        unit[j] = 1.0
        _, dp = model.gradient_soa(Q, unit, wrt="p")
        ginv[:, :, j] = dp.T
    return 0.5 * (ginv + ginv.transpose(0, 2, 1))


def spacetime_momenta(model, chart, S: np.ndarray, D: np.ndarray):
    """(Q, P) (4, N) for photons at spatial coords S seen along local Cartesian directions D."""
    n_rays = S.shape[1]
    Q = np.vstack([np.zeros((1, n_rays)), S])
    ginv = inverse_metric_soa(model, Q)
    with np.errstate(all="ignore"):
        g = np.linalg.inv(ginv)
    xi_t = np.zeros((n_rays, 4))
    xi_t[:, 0] = 1.0
    xi_phi = np.zeros((n_rays, 4))
    xi_phi[:, 1:] = chart.axial_killing(S).T
    g_tphi = _dot(g, xi_t, xi_phi)
    g_phiphi = _dot(g, xi_phi, xi_phi)
    omega = np.where(g_phiphi > 1e-300, -g_tphi / np.where(g_phiphi > 1e-300, g_phiphi, 1.0), 0.0)
    u = xi_t + omega[:, None] * xi_phi
    norm2 = _dot(g, u, u)
    if not np.all(norm2 < 0):
        raise InsideHorizonError("the camera is inside the black hole's horizon (or where no "
                                 "observer can stay at rest): move it further out")
    u /= np.sqrt(-norm2)[:, None]
    V = np.zeros((n_rays, 4, 3))
    for a in range(3):
        unit = np.zeros((3, n_rays))
        unit[a] = 1.0
        V[:, 1:, a] = chart.coord_directions(S, unit).T
    V += u[:, :, None] * np.einsum("nij,ni,nja->na", g, u, V)[:, None, :]  # project out u
    E = _orthonormalize(g, V)
    k = -u + np.einsum("nia,an->ni", E, D)
    P = np.ascontiguousarray(np.einsum("nij,nj->in", g, k))
    return Q, P


def _dot(g, a, b):
    """g(a, b) for batches of vectors (N, 4)."""
    return np.einsum("nij,ni,nj->n", g, a, b)


def _orthonormalize(g, V):
    """Symmetric orthonormalisation V (V^T g V)^(-1/2) of three spacelike vectors (N, 4, 3)."""
    G = np.einsum("nia,nij,njb->nab", V, g, V)
    w, U = np.linalg.eigh(G)
    if not np.all(w > 0):
        raise InsideHorizonError("the camera's spatial directions are not spacelike here "
                                 "(inside the horizon?): move the camera further out")
    inv_sqrt = np.einsum("nab,nb,ncb->nac", U, 1.0 / np.sqrt(w), U)
    return np.einsum("nia,nab->nib", V, inv_sqrt)


def medium_momenta(model, S: np.ndarray, D: np.ndarray):
    """(Q, P) (3, N) with p along D scaled so that H = 1/2 (H is quadratic in p)."""
    h = model.value_soa(S, D)
    with np.errstate(all="ignore"):
        scale = np.sqrt(0.5 / h)
    return S.copy(), D * scale
