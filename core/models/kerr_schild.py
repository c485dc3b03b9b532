"""Kerr in Cartesian Kerr–Schild coordinates, evaluated in its Kerr–Schild form by hand."""

from __future__ import annotations

import numpy as np

from .. import dual
from ..dual import Dual
from ..integrators.system import FrozenQ
from .base import Hamiltonian, blocked
from .expression import ExpressionHamiltonian
from .kerr_split import KerrBoyerLindquist


class KerrSchild(Hamiltonian):
    """Kerr in Cartesian Kerr–Schild coordinates: g^uv = eta^uv - f l^u l^v (docs/design.md).

    Evaluated in its Kerr–Schild form H = 1/2 eta^uv p_u p_v - 1/2 f (k.p)^2, where
    l.p = k(q).p is linear in p: f, the k_i and r are dual numbers over (x, y, z) only (t is
    cyclic; no momentum seeds), and
    dH/dp = eta p - f (k.p) k,  dH/dq = -1/2 (k.p)^2 df - f (k.p) p_i dk_i.
    The Poincaré time scale g = r comes out of the same evaluation. ``definition()`` is
    the same H as text (an ExpressionHamiltonian), which the tests evaluate with full
    dual numbers to check the hand-written form.
    """

    kind = "spacetime"

    def __init__(self, rg: float, a: float, horizon: float, outgoing: bool = False):
        super().__init__(
            ("t", "x", "y", "z"), ("p_t", "p_x", "p_y", "p_z"), parameters={"rg": rg, "a": a}
        )
        self.rg, self.a, self.horizon = rg, a, horizon
        self.outgoing = outgoing
        self._k_t = 1.0 if outgoing else -1.0

    @property
    def scales_time(self) -> bool:
        """g = r (the Kerr–Schild radius)."""
        return True

    def definition(self) -> ExpressionHamiltonian:
        """H as text over (t, x, y, z; p): the definition the fast form is checked against."""
        # ingoing: l_mu = (1, l_i(a)), regular on the future horizon; outgoing: the time
        # reverse of ingoing with spin -a, l_mu = (-1, l_i(-a)), regular on the past horizon
        # (the one rays traced backwards from a camera cross).
        s = "-" if self.outgoing else "+"
        o = "+" if self.outgoing else "-"
        k = [f"(r*x {s} a*y)/ra2", f"(r*y {o} a*x)/ra2", "z/r"]
        lp = f"{'' if self.outgoing else '-'}p_t + ({k[0]})*p_x + ({k[1]})*p_y + ({k[2]})*p_z"
        defs = [
            ("rho2", "x**2 + y**2 + z**2 - a**2"),
            ("r2", "0.5*(rho2 + sqrt(rho2**2 + 4*a**2*z**2))"),
            ("r", "sqrt(r2)"),
            ("f", "rg*r*r2/(r2**2 + a**2*z**2)"),
            ("ra2", "r2 + a**2"),
        ]
        text = "0.5*(-p_t**2 + p_x**2 + p_y**2 + p_z**2 - f*lp**2)"
        return ExpressionHamiltonian(
            text,
            self.coords,
            self.momenta,
            parameters=self.parameters,
            definitions=defs + [("lp", lp)],
            time_scale="sqrt(0.5*(x**2 + y**2 + z**2 - a**2 + "
            "sqrt((x**2 + y**2 + z**2 - a**2)**2 + 4*a**2*z**2)))",
        )

    def partials_allocated(self, q, p) -> set[str]:
        """Variables whose partial derivative H's evaluation carries: x, y, z (as far as the
        form depends on them) and every momentum; never t (cyclic)."""
        Q, _, _ = self._soa(q, p)
        keys: set[int] = set()
        for d in self._form_soa(Q, True):
            keys |= set(d.d)
        return {self.coords[k] for k in keys} | set(self.momenta)

    def kerr_orbits(self) -> tuple[float, float]:
        """(M, a): Kerr's own metric (see Hamiltonian.kerr_orbits)."""
        return self.mass, self.a

    def for_backward_tracing(self, explicit_split: bool = False) -> Hamiltonian:
        """The outgoing chart: rays followed into the past cross the past horizon smoothly.
        With ``explicit_split`` (and |a| < M): Kerr in Boyer–Lindquist with its explicit
        square-root split (core/models/kerr_split.py), in a chart on this one's frame."""
        if explicit_split and abs(self.a) < self.mass:
            return KerrBoyerLindquist(self.rg, self.a)
        return self if self.outgoing else KerrSchild(self.rg, self.a, self.horizon, True)

    # --- evaluation in Kerr–Schild form ---
    def _form_soa(self, Q, seed: bool):
        """f, k_x, k_y, k_z, r at Q: Duals over x, y, z (indices 1..3) if seed, else arrays.

        Written out by hand (about 60 array operations instead of ~250 dual ones: less
        Python time, which the render's threads would otherwise queue for); the same
        definitions as the text of H, which tests/core/test_kernels.py evaluates with duals
        to check it.
        With D = sqrt(rho2^2 + 4 a^2 z^2): dr/dx = x r/D, dr/dy = y r/D,
        dr/dz = z (r^2 + a^2)/(r D); f = rg r^3/W with W = r^4 + a^2 z^2.
        """
        x, y, z = Q[1], Q[2], Q[3]
        a, a2 = self.a, self.a * self.a
        sa = a if not self.outgoing else -a  # k_x = (r x + sa y)/ra2, k_y = (r y - sa x)/ra2
        rho2 = x * x + y * y + z * z - a2
        az2 = a2 * z * z
        D = np.sqrt(rho2 * rho2 + 4.0 * az2)
        r2 = 0.5 * (rho2 + D)
        r = np.sqrt(r2)
        ra2 = r2 + a2
        W = r2 * r2 + az2
        f = self.rg * r * r2 / W
        inv_ra2 = 1.0 / ra2
        kx = (r * x + sa * y) * inv_ra2
        ky = (r * y - sa * x) * inv_ra2
        kz = z / r
        if not seed:
            return [f, kx, ky, kz, r]
        c = r / D
        dr = (x * c, y * c, z * (ra2 / (r * D)))  # dr/dx, dr/dy, dr/dz
        # df_i = f (3 dr_i / r - dW_i / W), dW_i = 4 r^3 dr_i + 2 a^2 z [i = z]
        u = (3.0 / r - 4.0 * r * r2 / W) * f
        df = [u * dr[0], u * dr[1], u * dr[2] - (2.0 * a2 / W) * z * f]
        # dk_j/dx_i = (d numerator_j / dx_i - k_j 2 r dr_i) / ra2
        two_r = 2.0 * r
        dkx = [
            (dr[0] * x + r - kx * two_r * dr[0]) * inv_ra2,
            (dr[1] * x + sa - kx * two_r * dr[1]) * inv_ra2,
            (dr[2] * x - kx * two_r * dr[2]) * inv_ra2,
        ]
        dky = [
            (dr[0] * y - sa - ky * two_r * dr[0]) * inv_ra2,
            (dr[1] * y + r - ky * two_r * dr[1]) * inv_ra2,
            (dr[2] * y - ky * two_r * dr[2]) * inv_ra2,
        ]
        kz_r = kz / r
        dkz = [-kz_r * dr[0], -kz_r * dr[1], 1.0 / r - kz_r * dr[2]]
        return [
            Dual(v, {1: d[0], 2: d[1], 3: d[2]})
            for v, d in ((f, df), (kx, dkx), (ky, dky), (kz, dkz), (r, dr))
        ]

    # noqa: C901 below: one fused pass for every combination of H, dH/dq, dH/dp and K
    # (in place, the render's hot path); split up, it would evaluate the form's terms twice
    def _apply(self, form, P, want: str, H0=None):  # noqa: C901
        """(H, dH/dq, dH/dp) from the form [f, k_x, k_y, k_z, r], each None unless wanted
        ("v", "q", "p" in want). With H0: K = r (H - H0) and its gradient instead."""
        need_q = "q" in want
        if need_q:
            (f, df), (kx, dkx), (ky, dky), (kz, dkz), (r, dr) = ((d.v, d.d) for d in form)
        else:
            f, kx, ky, kz, r = (dual.value_of(d) for d in form)
        kt = self._k_t
        kp = kt * P[0] + kx * P[1] + ky * P[2] + kz * P[3]
        fkp = f * kp
        h = dh = None
        if "v" in want or (need_q and H0 is not None):
            h = P[1] * P[1] + P[2] * P[2] + P[3] * P[3] - P[0] * P[0] - fkp * kp
            h *= 0.5
            dh = None if H0 is None else h - H0
        dp = None
        if "p" in want:
            dp = np.empty_like(P)
            np.multiply(fkp, -kt, out=dp[0])
            dp[0] -= P[0]
            for i, k in ((1, kx), (2, ky), (3, kz)):
                np.multiply(fkp, k, out=dp[i])
                np.subtract(P[i], dp[i], out=dp[i])
            if H0 is not None:
                dp *= r
        dq = None
        if need_q:
            dq = np.empty_like(P)
            dq[0] = 0.0
            half_kp2 = -0.5 * kp * kp
            for j in (1, 2, 3):
                row = dq[j]
                row[:] = 0.0
                if j in df:
                    np.multiply(half_kp2, df[j], out=row)
                acc = None
                for i, dk in ((1, dkx), (2, dky), (3, dkz)):
                    if j in dk:
                        term = P[i] * dk[j]
                        acc = term if acc is None else acc + term
                if acc is not None:
                    acc *= fkp
                    row -= acc
                if dh is not None:
                    row *= r
                    if j in dr:
                        row += dr[j] * dh
        if h is not None and dh is not None:
            h = r * dh
        return (h if "v" in want else None), dq, dp

    @blocked
    def value_soa(self, Q, P):
        return self._apply(self._form_soa(Q, False), P, "v")[0]

    def _value_gradient(self, Q, P, wrt):
        return self._apply(self._form_soa(Q, "q" in wrt), P, "v" + wrt)

    def time_scale_soa(self, Q):
        """g = r (Kerr–Schild radius) and dr/dq."""
        r = self._form_soa(Q, True)[4]
        dr = np.zeros_like(Q)
        for j, g in r.d.items():
            dr[j] = g
        return r.v.copy(), dr

    @blocked
    def poincare_soa(self, Q, P, H0, wrt: str = "qp"):
        """(K = r (H - H0), dK/dq, dK/dp) in one evaluation: the derivatives not in wrt are
        None, and so is K when only dK/dp is asked for."""
        return self._apply(self._form_soa(Q, "q" in wrt), P, wrt if wrt == "p" else "v" + wrt, H0)

    def frozen_q(self, Q, H0=None) -> FrozenQ:
        """dH/dq at Q for any momenta (dK/dq of K = r (H - H0) with H0), see FrozenQ."""
        return FrozenQ(self._apply, self._form_soa(Q, True), H0)

    def radius_at(self, X: np.ndarray) -> np.ndarray:
        """Kerr–Schild r at local Cartesian positions X (3, N)."""
        return self.radius_soa(np.concatenate([np.zeros_like(X[:1]), X]))

    def radius_soa(self, Q):
        """Kerr–Schild r > 0 from r^4 - (x^2+y^2+z^2-a^2) r^2 - a^2 z^2 = 0."""
        x, y, z = Q[1], Q[2], Q[3]
        rho2 = x * x + y * y + z * z - self.a**2
        return np.sqrt(0.5 * (rho2 + np.sqrt(rho2 * rho2 + 4 * self.a**2 * z * z)))

    def capture_test(self):
        """Rays inside the outer horizon (see captured_soa)."""
        return self.captured_soa

    def captured_soa(self, Q) -> np.ndarray:
        """Rays inside the outer horizon, r < r+ (N,)."""
        return self.radius_soa(Q) < self.horizon

    def invariants_soa(self, Q, P):
        """E = -p_t and L_z = x p_y - y p_x."""
        return {"p_t": P[0].copy(), "L_z": Q[1] * P[2] - Q[2] * P[1]}
