"""Kerr light rays split explicitly, in Boyer–Lindquist coordinates.

Null geodesics of Kerr in BL (t, r, theta, phi) with E = -p_t, L = p_phi (t, phi cyclic)
have, in Mino time (K = Sigma H, Sigma = r^2 + a^2 cos^2 theta), the separated form

    K = 1/2 Delta p_r^2 + 1/2 p_theta^2 + L^2 / (2 sin^2 theta) - V,
    V = P(r)^2 / (2 Delta) + a E L - a^2 E^2 sin^2(theta) / 2 (+ H0 Sigma on H = H0),
    P = (r^2 + a^2) E - a L.

In s with r = M + b cosh s (b = sqrt(M^2 - a^2), ds = dr / sqrt(Delta), p_s = sqrt(Delta) p_r)

    K = T - V,   T = (p_s^2 + p_theta^2 + p_phi^2 / sin^2 theta) / 2:

free motion in s and on the unit sphere (T's angular part is the sphere's |J|^2 / 2, with
J the angular momentum of the direction n(theta, phi)), and a potential V with no 1/sin^2
at the poles. Fixed steps of Mino time are no good for rendering (far away a step covers a
distance ~ r^2), so the rays are followed on the level set T = V of the square-root
Hamiltonian

    Λ = 2 sqrt(T + c) - 2 sqrt(V + c),   c = C0 M^2 E^2 > 0,

whose flow is K's slowed by sqrt(T + c) (dσ = sqrt(V + c) dλ): the drift moves s and n at a
speed |(p_s, J)| / sqrt(T + c) < sqrt(2), so far away a step covers a fixed step in
s ~ ln r (a length ~ r, like the Kerr–Schild tracing's g = r), and c keeps Λ regular where
T = V = 0. Both parts are solved exactly (E and L are constants of both flows):

- drift (flow of 2 sqrt(T + c); R = sqrt(T + c) and J constant): s += t p_s / R, n turns
  about J by the angle t |J| / R (a great circle: exact through the poles, see
  sphere_geodesic), t_BL += -t 2 C0 M^2 E / R;
- kick (flow of -2 sqrt(V + c); s, theta fixed, w = 1 / sqrt(V + c)): p_s += t w dV/ds,
  p_theta += t w dV/dtheta, t_BL += t w (dV/dE + 2 c / E), phi += -t w dV/dL.

Λ is homogeneous of degree 1 in p: a ray's steps do not depend on its momentum's scale.
Λ is not of Runge–Kutta–Nyström type (its kinetic part is not quadratic in p, and depends
on theta), so the splittings for general A + B (core.integrators.splitting: blanes_moan_s6,
blanes_moan_s10) are the ones that keep their order on it. BL cannot cross the horizon: rays
moving in below r_capture (below every spherical photon orbit, see capture_radius) are
captured (falling_soa), so a camera anywhere outside r+ sees out along its outgoing rays.
The model is the renderer's form of a Kerr–Schild Kerr for an explicit splitting
(KerrSchild.for_backward_tracing): its chart (core.charts.KerrBLChart) maps positions to
and from the tracer's Kerr–Schild frame.

On rows with derivatives (core.dual.DualRows: ray differentials) the flows carry their tangent
map, written out (_drift_tangents, sphere_geodesic_tangents, _kick_tangents), for every
coordinate but t: t is cyclic and is read by nothing a ray's derivatives give (its escape
direction), so its derivative is left as it started, which saves a sixth of the work.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

from .. import dual
from ..charts import KerrBLChart
from ..dual import DualRows
from ..integrators.splitting import SplitSystem
from .base import Hamiltonian

C0 = 1.0
"""c = C0 M^2 E^2 in Λ (see the module)."""


def capture_radius(mass: float, a: float) -> float:
    """r+ + (r_ph - r+) / 2, with r_ph = 2 M (1 + cos(2/3 arccos(-|a|/M))) the innermost
    spherical photon orbit (prograde, equatorial): a ray followed backwards that gets below
    r_ph moving in cannot turn back out (no radial turning point there), so it is captured."""
    b = math.sqrt(max(mass * mass - a * a, 0.0))
    r_plus = mass + b
    r_ph = 2.0 * mass * (1.0 + math.cos(2.0 / 3.0 * math.acos(-abs(a) / mass)))
    return r_plus + 0.5 * (r_ph - r_plus)


class _Terms(NamedTuple):
    """What KerrBoyerLindquist's V and its derivatives are made of (``_terms``)."""

    E: Any
    L: Any
    sh: Any
    ch: Any
    r: Any
    delta: Any
    st: Any
    ct: Any
    ra2: Any
    pr: Any


class KerrBoyerLindquist(Hamiltonian):
    """Kerr in BL (t, s, theta, phi) with r = M + b cosh s: H = K / Sigma (see the module),
    offering the explicit split Λ (split_parts)."""

    kind = "spacetime"

    @property
    def chart(self) -> KerrBLChart:
        """(t, s, theta, phi), r = M + b cosh s, on the Kerr–Schild frame (core.charts)."""
        return KerrBLChart(self.mass, self.a)

    def __init__(self, rg: float, a: float):
        super().__init__(
            ("t", "s", "theta", "phi"),
            ("p_t", "p_s", "p_theta", "p_phi"),
            parameters={"rg": rg, "a": a},
        )
        self.rg, self.a = float(rg), float(a)
        m = self.mass
        if not abs(self.a) < m:
            raise ValueError(f"the BL split needs |a| < M (a non-extremal hole), got a/M = {a / m}")
        self.b = math.sqrt(m * m - self.a * self.a)
        self.horizon = m + self.b
        self.r_capture = capture_radius(m, self.a)
        self.s_capture = math.acosh((self.r_capture - m) / self.b)

    @property
    def scales_time(self) -> bool:
        """Λ's steps scale with the distance from the hole (see the module)."""
        return True

    def parts(
        self, Q: np.ndarray, P: np.ndarray, H0=0.0, derivatives: bool = True, sines=None,
        with_sigma: bool = True,
    ):  # fmt: skip
        """The potential V and its derivatives (dV/ds, dV/dtheta, dV/dE, dV/dL), with Sigma
        and (dSigma/ds, dSigma/dtheta); each (N,). V = P^2 / (2 Delta) + a E L
        - a^2 E^2 sin^2(theta) / 2 + H0 Sigma (the module's U plus L^2 / (2 sin^2 theta))
        (``sines``: (sin theta, cos theta) where the caller has them; without
        ``with_sigma``, Sigma and its derivatives are None where H0 is 0: the split's
        flows need V alone)."""
        return self._parts(self._terms(Q, P, sines), H0, derivatives, with_sigma)

    def _terms(self, Q: np.ndarray, P: np.ndarray, sines=None) -> _Terms:
        """What V and its derivatives are made of at (Q, P) (arrays or Duals)."""
        s, theta = Q[1], Q[2]
        E, L, a, b = -P[0], P[3], self.a, self.b
        sh, ch = dual.sinh(s), dual.cosh(s)
        r = self.mass + b * ch
        st, ct = (dual.sin(theta), dual.cos(theta)) if sines is None else sines
        ra2 = r * r + a * a
        return _Terms(E, L, sh, ch, r, (b * sh) ** 2, st, ct, ra2, ra2 * E - a * L)

    def _parts(self, t: _Terms, H0, derivatives: bool, with_sigma: bool = True):
        """``parts`` from its terms."""
        a, b = self.a, self.b
        level = isinstance(H0, dual.Dual) or np.ndim(H0) > 0 or H0 != 0.0  # H0 Sigma in V
        sigma = dsig = None
        if level or with_sigma:
            sigma = t.r * t.r + a * a * t.ct * t.ct
        with np.errstate(divide="ignore", invalid="ignore"):
            pr, E, L, st, ct = t.pr, t.E, t.L, t.st, t.ct
            V = pr * pr / (2.0 * t.delta) + a * E * L - 0.5 * (a * E * st) ** 2
            if level:
                V = V + H0 * sigma
            if not derivatives:
                return V, sigma
            if level or with_sigma:
                dsig = (2.0 * t.r * b * t.sh, -2.0 * a * a * ct * st)
            # d/ds of P^2/(2 Delta) = (P 2 r E / Delta - P^2 (r - M) / Delta^2) dr/ds, dr/ds = b sh
            dV_s = (pr * 2.0 * t.r * E - pr * pr * b * t.ch / t.delta) / (b * t.sh)
            dV_t = -a * a * E * E * st * ct
            if level and dsig is not None:
                dV_s = dV_s + H0 * dsig[0]
                dV_t = dV_t + H0 * dsig[1]
            dV_E = pr * t.ra2 / t.delta + a * L - a * a * E * st * st
            dV_L = -a * pr / t.delta + a * E
        return V, sigma, (dV_s, dV_t, dV_E, dV_L), dsig

    def curvature(self, Q: np.ndarray, P: np.ndarray, H0=0.0, sines=None):
        """V, its gradient (dV/ds, dV/dtheta, dV/dE, dV/dL) (``parts``) and its Hessian in
        (s, theta, E, L), for the kick's tangent map (SqrtSplit.kick on rows with
        derivatives): (V, gradient, H) with H the dict of second derivatives by pairs ("ss",
        "sE", ...; V_st = V_tL = 0; V_EE, which only t's derivative would need, is left
        out), each (N,). With r' = dr/ds = b sh, r'' = b ch,
        Delta = r'^2 and q = P / Delta, ``parts``' gradient reads V_s = 2 q r r' E
        - q^2 Delta_s / 2 + H0 Sigma_s, V_theta = -a^2 sin cos (E^2 + 2 H0),
        V_E = q (r^2 + a^2) + a L - a^2 E sin^2 theta, V_L = a (E - q): differentiated
        once more here."""
        terms = self._terms(Q, P, sines)
        V, _, gradient, _ = self._parts(terms, H0, True, with_sigma=False)
        E, a, b = terms.E, self.a, self.b
        r, r1, r2 = terms.r, b * terms.sh, b * terms.ch
        st, ct, delta, ra2 = terms.st, terms.ct, terms.delta, terms.ra2
        with np.errstate(divide="ignore", invalid="ignore"):
            q = terms.pr / delta
            delta_s, delta_ss = 2.0 * r1 * r2, 2.0 * (r2 * r2 + r1 * r1)
            rr1 = r * r1
            q_s = (2.0 * rr1 * E - q * delta_s) / delta
            q_E = ra2 / delta
            hessian = {
                "ss": 2.0 * E * (q_s * rr1 + q * (r1 * r1 + r * r2))
                - q * q_s * delta_s
                - 0.5 * q * q * delta_ss
                + H0 * 2.0 * (r1 * r1 + r * r2),
                "sE": 2.0 * rr1 * (q + E * q_E) - q * q_E * delta_s,
                "sL": -a * q_s,
                "tt": -a * a * (ct * ct - st * st) * (E * E + 2.0 * H0),
                "tE": -2.0 * a * a * E * st * ct,
                "EL": a * (1.0 - ra2 / delta),
                "LL": a * a / delta,
            }
        return V, gradient, hessian

    @staticmethod
    def kinetic(Q: np.ndarray, P: np.ndarray, sines=None):
        """T = (p_s^2 + p_theta^2 + p_phi^2 / sin^2 theta) / 2 and dT/dtheta, (N,)
        (``sines``: (sin theta, cos theta) where the caller has them)."""
        st, ct = (dual.sin(Q[2]), dual.cos(Q[2])) if sines is None else sines
        with np.errstate(divide="ignore", invalid="ignore"):
            l2 = P[3] * P[3] / (st * st)
            T = 0.5 * (P[1] * P[1] + P[2] * P[2] + l2)
            return T, -l2 * ct / st

    def value_soa(self, Q: np.ndarray, P: np.ndarray) -> np.ndarray:
        """H = (T - V) / Sigma, (N,)."""
        V, sigma = self.parts(Q, P, derivatives=False)
        return (self.kinetic(Q, P)[0] - V) / sigma

    def _value_gradient(self, Q, P, wrt):
        V, sigma, dV, dsig = self.parts(Q, P)
        T, dT_t = self.kinetic(Q, P)
        H = (T - V) / sigma
        dq = dp = None
        if "q" in wrt:
            dq = np.zeros_like(Q)
            dq[1] = (-dV[0] - H * dsig[0]) / sigma
            dq[2] = (dT_t - dV[1] - H * dsig[1]) / sigma
        if "p" in wrt:
            with np.errstate(divide="ignore", invalid="ignore"):
                dp_phi = P[3] / np.sin(Q[2]) ** 2 - dV[3]
            dp = np.stack([dV[2], P[1], P[2], dp_phi]) / sigma
        return H, dq, dp

    def kerr_orbits(self) -> tuple[float, float]:
        """(M, a): Kerr's own metric (see Hamiltonian.kerr_orbits)."""
        return self.mass, self.a

    def radius_at(self, X: np.ndarray) -> np.ndarray:
        """BL (= Kerr–Schild) r at local Cartesian positions X (3, N)."""
        x, y, z = X
        rho2 = x * x + y * y + z * z - self.a**2
        return np.sqrt(0.5 * (rho2 + np.sqrt(rho2 * rho2 + 4 * self.a**2 * z * z)))

    def capture_test(self):
        """Points at or past the horizon (see captured_soa)."""
        return self.captured_soa

    def captured_soa(self, Q: np.ndarray) -> np.ndarray:
        """Points at or past the horizon r+ (s <= 0, where a step past it lands, or NaN),
        (N,): only the rays' momenta tell whether one above r+ can still come out (see
        falling_soa)."""
        return ~(Q[1] > 0.0)

    def falling_soa(self, Q: np.ndarray, P: np.ndarray) -> np.ndarray:
        """Rays that can no longer come back out, (N,): at or past the horizon, or below
        r_capture moving in (p_s < 0; there is no radial turning point below r_ph). A
        camera between r+ and r_capture sees out along its outgoing rays."""
        return self.captured_soa(Q) | ((Q[1] < self.s_capture) & (P[1] < 0.0))

    def invariants_soa(self, Q, P):
        """E = -p_t, L = p_phi and the Carter constant (photons)."""
        cos2 = np.cos(Q[2]) ** 2
        carter = P[2] ** 2 + cos2 * (-(self.a**2) * P[0] ** 2 + P[3] ** 2 / (1.0 - cos2))
        return {"p_t": P[0].copy(), "p_phi": P[3].copy(), "carter": carter}

    def split_parts(self, H0=0.0, clocked: bool = False):
        """Λ = 2 sqrt(T + c) - 2 sqrt(U + c) with its exact drift and kick (the module); no
        clocked form."""
        if clocked:
            return None
        return SqrtSplit(self, H0)


class SqrtSplit(SplitSystem):
    """Λ = 2 sqrt(T + c) - 2 sqrt(V + c) of a KerrBoyerLindquist (see the module)."""

    separable = False  # T depends on theta (the sphere), both parts on E and L
    tangents = True

    def __init__(self, model: KerrBoyerLindquist, H0) -> None:
        self.model = model
        self.H0 = np.asarray(H0, dtype=np.float64)
        self.dim = 4
        self.c0 = C0 * model.mass**2
        self._kept: tuple | None = None  # (rows, theta, its sines): _sines

    def subset(self, keep) -> SqrtSplit:
        """The split for the rays keep (per-ray H0)."""
        return SqrtSplit(self.model, self.H0 if self.H0.ndim == 0 else self.H0[keep])

    def _root_T(self, Q: np.ndarray, P: np.ndarray, sines=None):
        """sqrt(T + c), dT/dtheta and E (``sines`` as ``kinetic``'s)."""
        T, dT_t = self.model.kinetic(Q, P, sines)
        E = -P[0]
        return dual.sqrt(T + self.c0 * E * E), dT_t, E

    def _root_V(self, Q: np.ndarray, P: np.ndarray):
        """1 / sqrt(V + c) and dV."""
        V, _, dV, _ = self.model.parts(Q, P, self.H0, sines=self._sines(Q), with_sigma=False)
        E = -P[0]
        with np.errstate(invalid="ignore", divide="ignore"):
            return 1.0 / dual.sqrt(V + self.c0 * E * E), dV

    def drift(self, Q: np.ndarray, P: np.ndarray, t) -> None:
        """Exact flow of 2 sqrt(T + c) over t: s moves at p_s / sqrt(T + c), the direction
        n on the unit sphere turns about the angular momentum J at |J| / sqrt(T + c)."""
        sines = self._sines(Q)  # theta's, shared: sin and cos cost the most here
        if isinstance(Q, DualRows):
            c, dc = self._drift_tangents(Q, P, t, sines)
            self._keep_sines(Q, sphere_geodesic_tangents(Q, P, c, dc, sines))
            return
        root, _, E = self._root_T(Q, P, sines)
        c = t / root
        Q[0] -= c * (2.0 * self.c0 * E)
        Q[1] += c * P[1]
        self._keep_sines(Q, sphere_geodesic(Q, P, c, sines))

    def _sines(self, Q: Any):
        """(sin theta, cos theta) of the rows Q: as the last drift on Q left them (its turn
        computes them: rho and down, to rounding), else computed (for Duals: None)."""
        if isinstance(Q, DualRows):
            theta = Q.value[2]
        elif isinstance(Q, np.ndarray):
            theta = Q[2]
        else:
            return None  # rows of Duals (tests): the plain code takes its own
        kept = self._kept
        if kept is not None and kept[0] is Q and np.array_equal(kept[1], theta):
            return kept[2]
        sines = np.sin(theta), np.cos(theta)
        self._kept = (Q, theta.copy(), sines)
        return sines

    def _keep_sines(self, Q: Any, sines) -> None:
        """Keep (sin theta, cos theta) of the rows Q as a drift left them (``_sines``)."""
        if sines is not None and isinstance(Q, DualRows | np.ndarray):
            theta = Q.value[2] if isinstance(Q, DualRows) else Q[2]
            self._kept = (Q, theta.copy(), sines)

    def _drift_tangents(self, Q: DualRows, P: Any, t, sines) -> tuple[np.ndarray, np.ndarray]:
        """The drift's move of s with its tangent map, written out (R = sqrt(T + c0 E^2),
        c = t / R, dc = -c dR / R, dR = (dT + 2 c0 E dE) / (2 R)), and t's move (its
        derivative not carried: see the module); -> (c, dc), for the sphere's turn
        (sphere_geodesic_tangents); ``sines``: (sin theta, cos theta)."""
        q, p, dq, dp = Q.value, P.value, Q.tangent, P.tangent
        E, L, p_s, p_theta = -p[0], p[3], p[1], p[2]
        st, ct = sines
        with np.errstate(divide="ignore", invalid="ignore"):
            spin = L / (st * st)
            l2 = spin * L
            root = np.sqrt(0.5 * (p_s * p_s + p_theta * p_theta + l2) + self.c0 * E * E)
            c = t / root
            rate = -0.5 * c / (root * root)
            dc = (rate * p_s) * dp[:, 1]
            dc += (rate * p_theta) * dp[:, 2]
            dc += (rate * spin) * dp[:, 3]
            dc -= (rate * l2 * ct / st) * dq[:, 2]
            dc -= (rate * 2.0 * self.c0 * E) * dp[:, 0]  # dE = -dp_t
        dq[:, 1] += p_s * dc
        dq[:, 1] += c * dp[:, 1]
        q[0] -= c * (2.0 * self.c0 * E)
        q[1] += c * p_s
        return c, dc

    def kick(self, Q: np.ndarray, P: np.ndarray, t) -> None:
        """Exact flow of -2 sqrt(V + c) over t ((s, theta), E, L fixed). On rows with
        derivatives (core.dual.DualRows) its tangent map is written out (_kick_tangents)."""
        if isinstance(Q, DualRows):
            self._kick_tangents(Q, P, t)
            return
        w, dV = self._root_V(Q, P)
        c = t * w
        P[1] += c * dV[0]
        P[2] += c * dV[1]
        Q[0] += c * (dV[2] + 2.0 * self.c0 * (-P[0]))
        Q[3] -= c * dV[3]

    def _kick_tangents(self, Q: DualRows, P: Any, t) -> None:
        """The kick and its tangent map: its increments depend on (s, theta, E, L) alone,
        so with c = t w, w = (V + c0 E^2)^(-1/2) and the gradient and Hessian of V
        (KerrBoyerLindquist.curvature), each increment's derivative is dc x + c dx, with
        dc = -t w^3 (dV + 2 c0 E dE) / 2; the per-ray coefficients are formed first, so each
        direction costs one product and one sum per term. t's derivative is not carried
        (see the module). The same numbers as the generic rows (core.dual) to rounding."""
        q, p, dq, dp = Q.value, P.value, Q.tangent, P.tangent
        V, (V_s, V_t, V_E, V_L), H = self.model.curvature(q, p, self.H0, self._sines(Q))
        E = -p[0]
        with np.errstate(invalid="ignore", divide="ignore"):
            w = 1.0 / np.sqrt(V + self.c0 * E * E)
        c = t * w
        clock = V_E + 2.0 * self.c0 * E
        rate = 0.5 * t * w**3  # dc = -rate (dV + 2 c0 E dE), with dE = -dp_t
        ds, d_theta, dp_t, dL = dq[:, 1], dq[:, 2], dp[:, 0], dp[:, 3]  # (k, N) each
        dc = (-rate * V_s) * ds
        dc -= (rate * V_t) * d_theta
        dc += (rate * clock) * dp_t
        dc -= (rate * V_L) * dL
        c_sL, c_tE, c_EL = c * H["sL"], c * H["tE"], c * H["EL"]
        dp[:, 1] += V_s * dc
        dp[:, 1] += (c * H["ss"]) * ds
        dp[:, 1] -= (c * H["sE"]) * dp_t
        dp[:, 1] += c_sL * dL
        dp[:, 2] += V_t * dc
        dp[:, 2] += (c * H["tt"]) * d_theta
        dp[:, 2] -= c_tE * dp_t
        dq[:, 3] -= V_L * dc
        dq[:, 3] -= c_sL * ds
        dq[:, 3] += c_EL * dp_t
        dq[:, 3] -= (c * H["LL"]) * dL
        p[1] += c * V_s
        p[2] += c * V_t
        q[0] += c * clock
        q[3] -= c * V_L

    def value_soa(self, Q: np.ndarray, P: np.ndarray) -> np.ndarray:
        """Λ(q, p), (N,)."""
        V, _ = self.model.parts(Q, P, self.H0, derivatives=False, with_sigma=False)
        root, _, E = self._root_T(Q, P)
        with np.errstate(invalid="ignore"):
            return 2.0 * root - 2.0 * np.sqrt(V + self.c0 * E * E)

    def gradient_soa(self, Q: np.ndarray, P: np.ndarray, wrt: str = "qp"):
        """(dΛ/dq or None, dΛ/dp or None), each (4, N)."""
        w, dV = self._root_V(Q, P)
        root, dT_t, E = self._root_T(Q, P)
        dq = dp = None
        if "q" in wrt:
            dq = np.zeros_like(Q)
            dq[1] = -w * dV[0]
            dq[2] = dT_t / root - w * dV[1]
        if "p" in wrt:
            dp = np.empty_like(P)
            dp[0] = -2.0 * self.c0 * E / root + w * (dV[2] + 2.0 * self.c0 * E)
            dp[1], dp[2] = P[1] / root, P[2] / root
            with np.errstate(divide="ignore", invalid="ignore"):
                dp[3] = P[3] / (np.sin(Q[2]) ** 2 * root) - w * dV[3]
        return dq, dp


def sphere_geodesic(Q: np.ndarray, P: np.ndarray, c, sines=None):
    """The flow of c (p_theta^2 + p_phi^2 / sin^2 theta) / 2 over unit time, in place on
    (theta, phi, p_theta, p_phi) = (Q[2], Q[3], P[2], P[3]): the unit vector n turns about
    J = p_theta e_phi - (p_phi / sin theta) e_theta by c |J| (a great circle, through the
    poles as well: no coordinate singularity in the flow; J_z = p_phi is kept). Written in
    the frame (e_rho, e_phi, z) at the old phi: n' = cos w n + sin w (J x n) / |J|
    (``sines``: (sin theta, cos theta) where the caller has them). -> (sin theta', cos
    theta') as it found them (rho and down; None on Duals)."""
    st, ct = (dual.sin(Q[2]), dual.cos(Q[2])) if sines is None else sines
    p_theta = P[2]
    with np.errstate(divide="ignore", invalid="ignore"):
        spin = P[3] / st  # (J x n) . e_phi
        size = dual.sqrt(p_theta * p_theta + spin * spin)
        omega = c * size
        cw = dual.cos(omega)
        sw = dual.sin(omega) / dual.where(dual.value_of(size) > 0, size, np.inf)
    along_rho = cw * st + sw * p_theta * ct  # n' . e_rho(phi)
    along_phi = sw * spin  # n' . e_phi(phi)
    rho = dual.sqrt(along_rho * along_rho + along_phi * along_phi)
    down = cw * ct - sw * p_theta * st
    Q[2] = dual.arctan2(rho, down)
    Q[3] += dual.arctan2(along_phi, along_rho)
    with np.errstate(divide="ignore", invalid="ignore"):
        # J . e_phi(phi'), with e_phi(phi') = cos d e_phi(phi) - sin d e_rho(phi)
        P[2] = (p_theta * along_rho + spin * ct * along_phi) / rho
    return (rho, down) if isinstance(rho, np.ndarray) else None


def sphere_geodesic_tangents(
    Q: DualRows, P: Any, c: np.ndarray, dc: np.ndarray, sines=None
) -> tuple[np.ndarray, np.ndarray]:
    """sphere_geodesic on rows with derivatives (core.dual.DualRows), its tangent map
    written out line by line (each quantity x beside its derivatives dx, (k, N), as sums of
    per-ray coefficients times derivatives), for a turn c with derivatives dc: the same
    numbers as sphere_geodesic on Duals, with a few times fewer array operations. The new
    direction is a unit vector, so with rho = sin theta' and down = cos theta',
    d theta' = -d(down) / rho and d rho = down d theta'. -> (rho, down)."""
    q, p, dq, dp = Q.value, P.value, Q.tangent, P.tangent
    theta, p_theta, L = q[2], p[2], p[3]
    d_theta, d_p_theta, dL = dq[:, 2], dp[:, 2], dp[:, 3]
    st, ct = (np.sin(theta), np.cos(theta)) if sines is None else sines
    with np.errstate(divide="ignore", invalid="ignore"):
        spin = L / st
        d_spin = (1.0 / st) * dL
        d_spin -= (spin * ct / st) * d_theta
        size = np.sqrt(p_theta * p_theta + spin * spin)
        inverse_size = np.where(size > 0, 1.0 / size, 0.0)
        d_size = (p_theta / size) * d_p_theta
        d_size += (spin / size) * d_spin
        omega = c * size
        d_omega = size * dc
        d_omega += c * d_size
        cw, sin_w = np.cos(omega), np.sin(omega)
        sw = sin_w * inverse_size
        d_sw = (cw * inverse_size) * d_omega
        d_sw -= (sw * inverse_size) * d_size
    along_rho = cw * st + sw * p_theta * ct
    down = cw * ct - sw * p_theta * st
    along_phi = sw * spin
    # d(along_rho), d(down): d(cos w) = -sin w d omega, d(sin θ) = cos θ dθ, d(cos θ) = -sin θ dθ
    d_rho_part = (-st * sin_w) * d_omega
    d_rho_part += (p_theta * ct) * d_sw
    d_rho_part += (sw * ct) * d_p_theta
    d_rho_part += down * d_theta
    d_down = (-ct * sin_w) * d_omega
    d_down -= (p_theta * st) * d_sw
    d_down -= (sw * st) * d_p_theta
    d_down -= along_rho * d_theta
    d_phi_part = spin * d_sw
    d_phi_part += sw * d_spin
    rho2 = along_rho * along_rho + along_phi * along_phi
    rho = np.sqrt(rho2)
    with np.errstate(divide="ignore", invalid="ignore"):
        new_p_theta = (p_theta * along_rho + spin * ct * along_phi) / rho
        d_new_theta = (-1.0 / rho) * d_down
        d_top = along_rho * d_p_theta
        d_top += p_theta * d_rho_part
        d_top += (along_phi * ct) * d_spin
        d_top -= (along_phi * spin * st) * d_theta
        d_top += (spin * ct) * d_phi_part
        dq[:, 3] += (along_rho / rho2) * d_phi_part
        dq[:, 3] -= (along_phi / rho2) * d_rho_part
        np.multiply(1.0 / rho, d_top, out=dp[:, 2])
        dp[:, 2] -= (new_p_theta * down / rho) * d_new_theta  # d rho = down d theta'
        dq[:, 2] = d_new_theta
    q[2] = np.arctan2(rho, down)
    q[3] += np.arctan2(along_phi, along_rho)
    p[2] = new_p_theta
    return rho, down
