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
from ..backend import array_module, asarray, is_array
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

    def curvature(self, Q: np.ndarray, P: np.ndarray, H0=0.0, sines=None, energy=True):
        """V, its gradient (dV/ds, dV/dtheta, dV/dE, dV/dL) (``parts``) and its Hessian in
        (s, theta, E, L), for the kick's tangent map (SqrtSplit.kick on rows with
        derivatives): (V, gradient, H) with H the dict of second derivatives by pairs ("ss",
        "sE", ...; V_st = V_tL = 0; V_EE, which only t's derivative would need, is left
        out), each (N,). With r' = dr/ds = b sh, r'' = b ch,
        Delta = r'^2 and q = P / Delta, ``parts``' gradient reads V_s = 2 q r r' E
        - q^2 Delta_s / 2 + H0 Sigma_s, V_theta = -a^2 sin cos (E^2 + 2 H0),
        V_E = q (r^2 + a^2) + a L - a^2 E sin^2 theta, V_L = a (E - q): differentiated
        once more here. Without ``energy`` the pairs with E ("sE", "tE", "EL") are left
        out (tangents along which E does not vary)."""
        terms = self._terms(Q, P, sines)
        V, _, gradient, _ = self._parts(terms, H0, True, with_sigma=False)
        E, a, b = terms.E, self.a, self.b
        r, r1, r2 = terms.r, b * terms.sh, b * terms.ch
        st, ct, delta, ra2 = terms.st, terms.ct, terms.delta, terms.ra2
        with np.errstate(divide="ignore", invalid="ignore"):
            q = terms.pr / delta
            delta_s, half_delta_ss = 2.0 * r1 * r2, r2 * r2 + r1 * r1
            rr1, sigma_ss = r * r1, r1 * r1 + r * r2  # Sigma_ss / 2
            q_s = (2.0 * rr1 * E - q * delta_s) / delta
            hessian = {
                "ss": 2.0 * (E * (q_s * rr1 + q * sigma_ss) + H0 * sigma_ss)
                - q * (q_s * delta_s + q * half_delta_ss),
                "sL": -a * q_s,
                "tt": -a * a * (ct * ct - st * st) * (E * E + 2.0 * H0),
                "LL": a * a / delta,
            }
            if energy:
                q_E = ra2 / delta
                hessian["sE"] = 2.0 * rr1 * (q + E * q_E) - q * q_E * delta_s
                hessian["tE"] = -2.0 * a * a * E * st * ct
                hessian["EL"] = a * (1.0 - ra2 / delta)
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

    def ray_capture_test(self):
        """Rays falling in for good (see falling_soa): the capture depends on the direction."""
        return self.falling_soa

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
        self.H0 = asarray(H0, dtype=np.float64)
        self.dim = 4
        self.c0 = C0 * model.mass**2
        self._kept: tuple | None = None  # (rows, theta, its sines): _sines
        self.energy_varies: bool | None = None  # along any tangent (gauge_tangents)

    def subset(self, keep) -> SqrtSplit:
        """The split for the rays keep (per-ray H0)."""
        split = SqrtSplit(self.model, self.H0 if self.H0.ndim == 0 else self.H0[keep])
        split.energy_varies = self.energy_varies  # a subset's rays vary no more
        return split

    def gauge_tangents(self, Q: np.ndarray, P: np.ndarray, dQ: np.ndarray, dP: np.ndarray) -> None:
        """Take out of the tangents their part along (0, p): Λ is homogeneous of degree 1
        in p (for light, H0 = 0), so its flows (and a step's map) carry (0, p) to (0, p'),
        which moves no position and no direction a ray leaves along. Then dE = -dp_t = 0
        on every ray, E is conserved, and the kick and the drift skip E's terms."""
        with np.errstate(divide="ignore", invalid="ignore"):
            scale = dP[:, 0] / P[0]  # (k, N)
        scalable = np.isfinite(scale)  # E = 0 (inside the ergoregion): left as it is
        scale[~scalable] = 0.0
        dP -= scale[:, None, :] * P
        dP[:, 0][scalable] = 0.0
        self.energy_varies = bool(dP[:, 0].any())  # read once here, not in every flow

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
            self._keep_sines(Q, self._drift_tangents(Q, P, t, sines))
            return
        root, _, E = self._root_T(Q, P, sines)
        c = t / root
        Q[0] -= c * (2.0 * self.c0 * E)
        Q[1] += c * P[1]
        self._keep_sines(Q, sphere_geodesic(Q, P, c, sines))

    def _sines(self, Q: Any):
        """(sin theta, cos theta) of the rows Q: as the last drift on Q left them (its turn
        computes them: rho and down, to rounding), else computed (for Duals: None). On a
        device, ray by ray: whether the kept theta still holds is not read back to the host
        (a sync in every flow, and no step a CUDA graph could capture)."""
        if isinstance(Q, DualRows):
            theta = Q.value[2]
        elif is_array(Q):
            theta = Q[2]
        else:
            return None  # rows of Duals (tests): the plain code takes its own
        kept = self._kept
        if kept is not None and kept[0] is Q:
            if isinstance(theta, np.ndarray):
                if np.array_equal(kept[1], theta):
                    return kept[2]
            else:
                same, (sin, cos) = kept[1] == theta, kept[2]
                xp = array_module(theta)
                return xp.where(same, sin, np.sin(theta)), xp.where(same, cos, np.cos(theta))
        sines = np.sin(theta), np.cos(theta)
        self._kept = (Q, theta.copy(), sines)
        return sines

    def _keep_sines(self, Q: Any, sines) -> None:
        """Keep (sin theta, cos theta) of the rows Q as a drift left them (``_sines``)."""
        if sines is not None and (isinstance(Q, DualRows) or is_array(Q)):
            theta = Q.value[2] if isinstance(Q, DualRows) else Q[2]
            self._kept = (Q, theta.copy(), sines)

    def _energy_varies(self, dp_t: Any) -> bool:
        """Whether E varies along any tangent dp_t (k, N) (dE = -dp_t): read from the rows
        on the host; on a device, what gauge_tangents found for the batch (a read in every
        flow would be a sync), else the rows'."""
        if isinstance(dp_t, np.ndarray) or self.energy_varies is None:
            return bool(dp_t.any())
        return self.energy_varies

    def _drift_tangents(self, Q: DualRows, P: Any, t, sines) -> tuple[np.ndarray, np.ndarray]:
        """The drift and its tangent map, written out: R = sqrt(T + c0 E^2) with T = (p_s^2
        + |J|^2) / 2, the turn c = t / R with dc = -c dR / R, R dR = p_s dp_s + |J| d|J|
        + 2 c0 E dE (E's term only where E varies: ``gauge_tangents``), s's move, then the
        sphere's turn (sphere_geodesic_tangents); t's derivative is not carried (see the
        module). ``sines``: (sin theta, cos theta). -> (sin theta', cos theta')."""
        q, p, dq, dp = Q.value, P.value, Q.tangent, P.tangent
        E, p_s = -p[0], p[1]
        start = sphere_start(p[2], p[3], sines, dq[:, 2], dp[:, 2], dp[:, 3])
        with np.errstate(divide="ignore", invalid="ignore"):
            root = np.sqrt(0.5 * (p_s * p_s + start.size2) + self.c0 * E * E)
            c = t / root
            rate = -0.5 * c / (root * root)  # dc = rate (R dR) 2 / 2
            dc = (rate * p_s) * dp[:, 1]
            dc += (rate * start.size) * start.along  # |J| d|J|
            if self._energy_varies(dp[:, 0]):  # dE = -dp_t
                dc -= (rate * 2.0 * self.c0 * E) * dp[:, 0]
        dq[:, 1] += p_s * dc
        dq[:, 1] += c * dp[:, 1]
        q[0] -= c * (2.0 * self.c0 * E)
        q[1] += c * p_s
        return sphere_geodesic_tangents(Q, P, c, dc, start)

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
        direction costs one product and one sum per term. E's terms are skipped where E
        does not vary (``gauge_tangents``); t's derivative is not carried (see the module).
        The same numbers as the generic rows (core.dual) to rounding."""
        q, p, dq, dp = Q.value, P.value, Q.tangent, P.tangent
        ds, d_theta, dp_t, dL = dq[:, 1], dq[:, 2], dp[:, 0], dp[:, 3]  # (k, N) each
        energy = self._energy_varies(dp_t)  # dE = -dp_t
        V, (V_s, V_t, V_E, V_L), H = self.model.curvature(
            q, p, self.H0, self._sines(Q), energy=energy
        )
        E = -p[0]
        with np.errstate(invalid="ignore", divide="ignore"):
            w = 1.0 / np.sqrt(V + self.c0 * E * E)
        c = t * w
        clock = V_E + 2.0 * self.c0 * E
        rate = (0.5 * c) * (w * w)  # dc = -rate (dV + 2 c0 E dE)
        dc = (-rate * V_s) * ds
        dc -= (rate * V_t) * d_theta
        dc -= (rate * V_L) * dL
        c_sL = c * H["sL"]
        if energy:
            dc += (rate * clock) * dp_t
            dp[:, 1] -= (c * H["sE"]) * dp_t
            dp[:, 2] -= (c * H["tE"]) * dp_t
            dq[:, 3] += (c * H["EL"]) * dp_t
        dp[:, 1] += V_s * dc
        dp[:, 1] += (c * H["ss"]) * ds
        dp[:, 1] += c_sL * dL
        dp[:, 2] += V_t * dc
        dp[:, 2] += (c * H["tt"]) * d_theta
        dq[:, 3] -= V_L * dc
        dq[:, 3] -= c_sL * ds
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
    rho, down = _turn_end(Q, P, (st, ct), spin, cw, sw)
    return (rho, down) if is_array(rho) else None


def _turn_end(Q: Any, P: Any, sines, spin, cw, sw):
    """The end of sphere_geodesic's turn by w, in place on (theta, phi, p_theta): n' in
    the frame (e_rho, e_phi, z) at the old phi, from cw = cos w and sw = sin w / |J|
    (arrays or Duals). -> (rho, down) = (sin theta', cos theta')."""
    (st, ct), p_theta = sines, P[2]
    along_rho = cw * st + sw * p_theta * ct  # n' . e_rho(phi)
    along_phi = sw * spin  # n' . e_phi(phi)
    rho = dual.sqrt(along_rho * along_rho + along_phi * along_phi)
    down = cw * ct - sw * p_theta * st
    with np.errstate(divide="ignore", invalid="ignore"):
        # J . e_phi(phi'), with e_phi(phi') = cos d e_phi(phi) - sin d e_rho(phi)
        new_p_theta = (p_theta * along_rho + spin * ct * along_phi) / rho
    Q[2] = dual.arctan2(rho, down)
    Q[3] += dual.arctan2(along_phi, along_rho)
    P[2] = new_p_theta
    return rho, down


class SphereStart(NamedTuple):
    """A drift's start on the unit sphere (sphere_start): J's parts, its heading and the
    direction's derivatives in the frame that moves with it (sphere_geodesic_tangents)."""

    sines: tuple[np.ndarray, np.ndarray]  # (sin theta, cos theta)
    spin: np.ndarray  # L / sin theta: J x n along e_phi
    size2: np.ndarray  # |J|^2
    size: np.ndarray  # |J|
    moving: np.ndarray  # J != 0 (bool): where the turn moves the direction
    inverse: np.ndarray  # 1 / |J| (0 where J = 0)
    heading: tuple[np.ndarray, np.ndarray]  # (cos chi, sin chi): e_theta to the motion
    along: np.ndarray  # (k, N): the velocity's derivative along the motion, d|J|
    across: np.ndarray  # (k, N): across it, along J / |J|


def sphere_start(
    p_theta: np.ndarray, L: np.ndarray, sines: tuple[np.ndarray, np.ndarray],
    d_theta: np.ndarray, d_p_theta: np.ndarray, dL: np.ndarray,
) -> SphereStart:  # fmt: skip
    """The start of a turn on the sphere with its derivatives (SphereStart): the motion
    p_theta e_theta + spin e_phi at the angle chi from e_theta (chi = 0 where J = 0: the
    turn then moves nothing), the derivative of that velocity (its covariant one: e_theta
    and e_phi are parallel along e_theta) is d p_theta e_theta + d spin e_phi, with
    d spin = dL / sin theta - spin cot theta d theta."""
    st, ct = sines
    with np.errstate(divide="ignore", invalid="ignore"):
        spin = L / st
        size2 = p_theta * p_theta + spin * spin
        size = np.sqrt(size2)
        moving = size > 0
        inverse = np.where(moving, 1.0 / size, 0.0)
        cos_h, sin_h = np.where(moving, p_theta * inverse, 1.0), spin * inverse
        d_spin = (1.0 / st) * dL
        d_spin -= (spin * ct / st) * d_theta
    along = cos_h * d_p_theta
    along += sin_h * d_spin
    across = cos_h * d_spin
    across -= sin_h * d_p_theta
    return SphereStart(sines, spin, size2, size, moving, inverse, (cos_h, sin_h), along, across)


def sphere_geodesic_tangents(
    Q: DualRows, P: Any, c: np.ndarray, dc: np.ndarray, start: SphereStart
) -> tuple[np.ndarray, np.ndarray]:
    """sphere_geodesic on rows with derivatives (core.dual.DualRows) for a turn c with
    derivatives dc, its tangent map written out in the frame that moves with the
    direction n: T (the motion, at the angle chi from e_theta) and B = J / |J|, both
    parallel along the great circle. Over the angle w = c |J| a derivative x T + y B of n
    with velocity derivative u T + v B (``start``) becomes x' = x + d(c |J|) (along the
    circle) and the Jacobi field of the unit sphere across it, y' = y cos w
    + v sin w / |J|, v' = v cos w - y |J| sin w, u' = u; back in (e_theta, e_phi) at the
    end (heading chi'), d phi = (x' sin chi' + y' cos chi') / sin theta' and
    d p_theta = u cos chi' - v' sin chi' + spin' cos theta' d phi (e_theta turns
    along e_phi). The same numbers as sphere_geodesic on Duals to rounding, with a
    few times fewer array operations. -> (sin theta', cos theta')."""
    q, p, dq, dp = Q.value, P.value, Q.tangent, P.tangent
    cos_h, sin_h = start.heading
    d_theta = dq[:, 2]
    size, spin = start.size, start.spin
    omega = c * size
    cw, sin_w = np.cos(omega), np.sin(omega)
    sw = np.where(start.moving, sin_w * start.inverse, c)  # sin w / |J|
    rho, down = _turn_end(q, p, start.sines, spin, cw, sw)  # p[2] is p_theta' from here
    with np.errstate(divide="ignore", invalid="ignore"):
        new_spin = p[3] / rho
        cos_end = np.where(start.moving, p[2] * start.inverse, 1.0)
        sin_end = new_spin * start.inverse
        x = cos_h * d_theta  # along the circle
        x += c * start.along
        x += size * dc
        y = (-sin_h * cw) * d_theta  # across it
        y += sw * start.across
        v = (start.size2 * sw * sin_h) * d_theta
        v += cw * start.across
        d_phi = (sin_end / rho) * x
        d_phi += (cos_end / rho) * y
    np.multiply(cos_end, x, out=dq[:, 2])
    dq[:, 2] -= sin_end * y
    dq[:, 3] += d_phi
    np.multiply(cos_end, start.along, out=dp[:, 2])
    dp[:, 2] -= sin_end * v
    dp[:, 2] += (new_spin * down) * d_phi
    return rho, down
