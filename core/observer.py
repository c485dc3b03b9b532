"""Initial ray momenta in the observer's local orthonormal frame (docs/design.md, "Observer").

For a spacetime the observer is the zero-angular-momentum observer u ∝ ξ_t + ω ξ_φ
(ω = −g(ξ_t, ξ_φ)/g(ξ_φ, ξ_φ)); without frame dragging that is the static observer.
Its spatial triad is the symmetric (Löwdin) orthonormalisation of the coordinate
images of the local Cartesian axes, so in flat space the frame is exactly the world's
axes and the rays are exactly Blender's. A photon *seen* along direction d arrives with
k = u − d; we trace it backwards, i.e. forwards with p = g(−u + d) (H is even in p).
"""

from __future__ import annotations

import numpy as np

from .backend import array_module, to_host


class ObserverError(ValueError):
    """No observer frame can be set up where the rays start (the camera); subclasses say why."""


class InsideHorizonError(ObserverError):
    """The camera is inside a horizon: no static or zero-angular-momentum observer exists."""


class CoordinateAxisError(ObserverError):
    """The camera is on the polar axis of spherical / Boyer–Lindquist coordinates."""


class SingularMetricError(ObserverError):
    """The metric is singular (or not finite) at the camera."""


class MetricSignatureError(ObserverError):
    """The metric at the camera is not of signature (-, +, +, +)."""


_AXIS = 1e-6
"""|sin theta| below which a camera counts as on the polar axis of a spherical chart."""
_SINGULAR = 1e-14
"""A metric whose eigenvalues' smallest |w| is below this times the largest is called
singular (a few float64 epsilons: the accuracy of the eigenvalues themselves)."""


def inverse_metric_soa(model, Q: np.ndarray) -> np.ndarray:
    """g^{ij}(q) as (N, n, n), read off a Hamiltonian quadratic in p: dH/dp_i at p = e_j."""
    n, n_rays = Q.shape
    ginv = np.empty_like(Q, shape=(n_rays, n, n))
    for j in range(n):
        unit = np.zeros_like(Q)
        unit[j] = 1.0
        _, dp = model.gradient_soa(Q, unit, wrt="p")
        ginv[:, :, j] = dp.T
    return 0.5 * (ginv + ginv.transpose(0, 2, 1))


def spacetime_momenta(model, chart, S: np.ndarray, D: np.ndarray):
    """(Q, P) (4, N) for photons at spatial coords S seen along local Cartesian directions D.
    The observer's frame is set up once per distinct start (a camera's rays share one)."""
    n_rays, xp = S.shape[1], array_module(S)
    if n_rays and (S == S[:, :1]).all():  # one camera's rays: no sort
        points, where = S[:, :1], xp.zeros(n_rays, dtype=np.intp)
    else:
        points, where = np.unique(S, axis=1, return_inverse=True)
        where = where.reshape(-1)
    # the frames at the few distinct starts are set up on the host (core.backend)
    g, u, E = (xp.asarray(a) for a in _observer_frames(model, chart, to_host(points)))
    k = -u[where] + np.einsum("nia,an->ni", E[where], D)
    P = np.einsum("nij,nj->in", g[where], k).copy()  # C-contiguous rows
    return xp.concatenate([xp.zeros((1, n_rays)), S]), P


def observer_frame(model, chart, S: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """At one point S (3, 1) of chart coords: the metric g (4, 4), the static / ZAMO
    observer's u (4,) and its spatial triad E (4, 3) (the local Cartesian axes)."""
    g, u, E = _observer_frames(model, chart, S)
    return g[0], u[0], E[0]


def _observer_frames(model, chart, S: np.ndarray):
    """At spatial coords S (3, N): the metric g (N, 4, 4), the observer's u (N, 4) and its
    spatial triad E (N, 4, 3) (the module); an ObserverError where none exists."""
    n_rays = S.shape[1]
    Q, ginv, g = _metric(model, S)
    if g is None:
        raise _diagnose(model, chart, Q, ginv, np.ones(n_rays, dtype=bool))
    xi_t = np.zeros((n_rays, 4))
    xi_t[:, 0] = 1.0
    xi_phi = _axial_vector(chart, S)
    omega = zamo_omega(_dot(g, xi_t, xi_phi), _dot(g, xi_phi, xi_phi))
    u = xi_t + omega[:, None] * xi_phi
    norm2 = _dot(g, u, u)
    if not np.all(norm2 < 0):
        raise _diagnose(model, chart, Q, ginv, ~(norm2 < 0))
    u /= np.sqrt(-norm2)[:, None]
    V = np.zeros((n_rays, 4, 3))
    for a in range(3):
        unit = np.zeros((3, n_rays))
        unit[a] = 1.0
        V[:, 1:, a] = chart.coord_directions(S, unit).T
        V[:, 0, a] = chart.coord_time(S, unit)  # charts whose time slices differ (kerr_bl)
    V += u[:, :, None] * np.einsum("nij,ni,nja->na", g, u, V)[:, None, :]  # project out u
    E, spacelike = _orthonormalize(g, V)
    if not spacelike.all():
        raise _diagnose(model, chart, Q, ginv, ~spacelike)
    return g, u, E


def _metric(model, S: np.ndarray):
    """At spatial coords S (3, N): Q (4, N) at t = 0, g^ij and g_ij (N, 4, 4); g_ij None
    where g^ij cannot be inverted."""
    Q = np.concatenate([np.zeros_like(S[:1]), S])
    with np.errstate(all="ignore"):
        ginv = inverse_metric_soa(model, Q)
        try:
            return Q, ginv, np.linalg.inv(ginv)
        except np.linalg.LinAlgError:
            return Q, ginv, None


def _axial_vector(chart, S: np.ndarray) -> np.ndarray:
    """ξ_φ (N, 4), the rotation about z, at spatial coords S (3, N)."""
    xi_phi = np.zeros_like(S, shape=(S.shape[1], 4))
    xi_phi[:, 1:] = chart.axial_killing(S).T
    return xi_phi


def zamo_omega(g_tphi: np.ndarray, g_phiphi: np.ndarray) -> np.ndarray:
    """Angular velocity ω = −g(ξ_t, ξ_φ) / g(ξ_φ, ξ_φ) of the zero-angular-momentum observer
    (0 on the axis, where g(ξ_φ, ξ_φ) = 0)."""
    on_axis = ~(g_phiphi > 1e-300)
    return np.where(on_axis, 0.0, -g_tphi / np.where(on_axis, 1.0, g_phiphi))


def killing_block(model, chart, S: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(g_tt, g_tφ, g_φφ), each (N,): the metric on the Killing vectors ξ_t, ξ_φ (rotation
    about z) at spatial coordinates S (3, N) of a spacetime's chart, or of a static optical
    medium that knows its time metric (``killing_block_soa``: Schwarzschild's isotropic
    form). NaN where the metric is singular."""
    if chart.time_index is None:
        return model.killing_block_soa(S)
    _, _, g = _metric(model, S)
    if g is None:
        nan = np.full_like(S[0], np.nan)
        return nan, nan, nan
    xi_phi = _axial_vector(chart, S)
    return g[:, 0, 0], np.einsum("ni,ni->n", g[:, 0, :], xi_phi), _dot(g, xi_phi, xi_phi)


def killing_energy(block, p_t, p_phi, omega) -> np.ndarray:
    """p·u (N,) of covariant momenta with components p_t = p·ξ_t, p_φ = p·ξ_φ, for the unit
    observers u = u^t (ξ_t + Ω ξ_φ), u^t > 0, of angular velocities ``omega`` at the points
    of ``block`` (killing_block); NaN where such an observer is not timelike."""
    g_tt, g_tphi, g_phiphi = block
    norm2 = g_tt + 2.0 * omega * g_tphi + omega * omega * g_phiphi
    with np.errstate(all="ignore"):
        return (p_t + omega * p_phi) / np.sqrt(-norm2)


def _dot(g, a, b):
    """g(a, b) for batches of vectors (N, 4)."""
    return np.einsum("nij,ni,nj->n", g, a, b)


def _orthonormalize(g, V):
    """Symmetric orthonormalisation V (V^T g V)^(-1/2) of three vectors (N, 4, 3), and
    (N,) whether they were spacelike (where not, the frame is meaningless)."""
    G = np.einsum("nia,nij,njb->nab", V, g, V)
    w, U = np.linalg.eigh(G)
    spacelike = np.all(w > 0, axis=1)
    with np.errstate(all="ignore"):
        inv_sqrt = np.einsum("nab,nb,ncb->nac", U, 1.0 / np.sqrt(w), U)
    return np.einsum("nia,nab->nib", V, inv_sqrt), spacelike


def medium_momenta(model, S: np.ndarray, D: np.ndarray):
    """(Q, P) (3, N) with p along D scaled so that H = 1/2 (H is quadratic in p)."""
    h = model.value_soa(S, D)
    with np.errstate(all="ignore"):
        scale = np.sqrt(0.5 / h)
    return S.copy(), D * scale


def _diagnose(model, chart, Q: np.ndarray, ginv: np.ndarray, bad: np.ndarray) -> ObserverError:
    """Why no observer frame exists at the ray starts ``bad`` ((N,) bool) of Q (4, N):
    on a spherical chart's axis, inside the horizon, g^ij singular, of the wrong
    signature, or (a valid metric) no observer at rest there. Only runs on failure."""
    Q, ginv = Q[:, bad], ginv[bad]
    if chart.polar_axis and np.any(np.abs(np.sin(Q[2])) < _AXIS):
        return CoordinateAxisError(
            "the camera is on the polar axis (theta = 0 or pi) of the model's spherical / "
            "Boyer–Lindquist coordinates, where they are singular: move it off the axis "
            "(x = y = 0 in the centre's frame), or use the Kerr–Schild chart" + chart.axis_hint
        )
    inside = _inside_horizon(model, Q)
    if inside.any():
        return _no_rest(model, Q[:, inside])
    finite = np.isfinite(ginv).all(axis=(1, 2))
    w = np.linalg.eigvalsh(np.where(finite[:, None, None], ginv, 0.0))
    size = np.abs(w)
    singular = ~finite | (size.min(axis=1) <= _SINGULAR * size.max(axis=1))
    if singular.any():
        return _singular(model, Q[:, np.argmax(singular)])
    lorentzian = (np.sum(w < 0, axis=1) == 1) & (np.sum(w > 0, axis=1) == 3)
    if not lorentzian.all():
        return _signature(model, Q[:, np.argmin(lorentzian)], w[np.argmin(lorentzian)])
    return _no_rest(model, Q)


def _signature(model, q: np.ndarray, w: np.ndarray) -> MetricSignatureError:
    """The error for a ray start q (4,) where g^ij has eigenvalues w of the wrong signs."""
    signs = ", ".join("-" if x < 0 else "+" for x in np.sort(w))
    hint = " (a metric written as (+, -, -, -) must be negated)" if np.sum(w < 0) == 3 else ""
    return MetricSignatureError(
        f"the metric has signature ({signs}) at the camera ({_where(model, q)}); SymRay "
        f"needs (-, +, +, +): one time coordinate and three space coordinates{hint}"
    )


def _singular(model, q: np.ndarray) -> SingularMetricError:
    """The error for a ray start q (4,) where g^ij is not finite or not invertible."""
    return SingularMetricError(
        f"the inverse metric g^ij is singular at the camera ({_where(model, q)}): not "
        "finite, or of determinant 0 (e.g. all entries zero); a metric must be invertible "
        "where the rays start"
    )


def _no_rest(model, Q: np.ndarray) -> InsideHorizonError:
    """The error for ray starts (4, M) with a valid metric but no observer at rest there."""
    if _inside_horizon(model, Q).any() or model.rg > 0:
        return InsideHorizonError(
            f"the camera ({_where(model, Q[:, 0])}) is inside the black hole's horizon: no "
            "light from there reaches the outside; move it further from the centre"
        )
    return InsideHorizonError(
        f"no observer can stay at rest at the camera ({_where(model, Q[:, 0])}): the metric's "
        "time direction is not timelike there (inside a horizon or an ergoregion of the "
        "metric?); move the camera"
    )


def _inside_horizon(model, Q: np.ndarray) -> np.ndarray:
    """(M,) bool: the points Q (4, M) inside the model's horizon (its capture test)."""
    captured = model.capture_test()
    if captured is None:
        return np.zeros(Q.shape[1], dtype=bool)
    with np.errstate(all="ignore"):
        return np.asarray(captured(Q), dtype=bool)


def _where(model, q: np.ndarray) -> str:
    """'at (t, x, y, z) = (...)' for one point of the model's coordinates."""
    coords = model.coords
    names = ", ".join(coords) if len(coords) == len(q) else "q"
    return f"at ({names}) = ({', '.join(f'{v:.4g}' for v in q)})"


def check_camera(tracer, position) -> None:
    """Raise the ObserverError that tracing rays from world ``position`` would meet.

    Only spacetimes have an observer (and a medium with a horizon, Schwarzschild's optical
    form, a camera that must be outside it), and only a camera inside the model's region
    starts rays where it is (others start on the region's boundary, far from the mass).
    """
    if not tracer.curved:
        return
    X = (
        np.asarray(position, dtype=np.float64).reshape(1, 3) - tracer.scene.center
    ) @ tracer.rotation
    _, inside = tracer.region.entry(X, np.array([[0.0, 0.0, 1.0]]))
    if not inside[0]:
        return
    if not tracer.spacetime:
        model = tracer.model
        if model.horizon > 0 and not (model.radius_at(X.T) > model.horizon).all():
            raise _no_rest(model, X.T)
        return
    S = tracer.chart.to_coords(X.T)
    if _inside_horizon(tracer.model, np.vstack([np.zeros((1, 1)), S])).any():
        # every ray would end at once (inside r- an observer exists, but sees nothing)
        raise _no_rest(tracer.model, np.vstack([np.zeros((1, 1)), S]))
    spacetime_momenta(tracer.model, tracer.chart, S, np.array([[0.0], [0.0], [1.0]]))
