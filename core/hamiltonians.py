"""Hamiltonian models: user expressions, metrics (seed Eq. 10), black holes and media.

Every model is a :class:`Hamiltonian`. Internally arrays are structure-of-arrays with
rays on the last axis (``Q``, ``P`` of shape ``(n, N)``); the public ``value`` and
``gradient`` take the contract's ``(N, n)`` or ``(n,)`` arrays. Partial derivatives
come from :mod:`core.dual`, carrying only the partials each quantity depends on.

Signature (-, +, +, +) throughout; photons have H = 1/2 g^ij p_i p_j = 0.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence

import numpy as np

from . import checks, dual
from . import expressions as ex
from .dual import Dual

BLOCK = 8192
"""Evaluations of more rays than 2 * BLOCK go block by block: the temporaries of one block
stay small (numpy temporaries of a few hundred kB are allocated fresh, page by page, and
cost more than the arithmetic on them), and the outputs are filled in place."""


def blocked(method):
    """Run a model's SoA evaluation (self, Q, *per-ray args) in blocks of BLOCK rays.

    Arguments that are arrays with rays on the last axis are cut into blocks; the results
    (an array, or a tuple of arrays and Nones) are assembled along the last axis.
    """

    @functools.wraps(method)
    def wrapper(self, Q, *args, **kwargs):
        n_rays = Q.shape[-1]
        if n_rays <= 2 * BLOCK:
            return method(self, Q, *args, **kwargs)
        out = None
        for start in range(0, n_rays, BLOCK):
            cut = slice(start, min(start + BLOCK, n_rays))
            part = method(self, Q[..., cut], *(
                a[..., cut] if isinstance(a, np.ndarray) and a.ndim and a.shape[-1] == n_rays
                else a for a in args), **kwargs)
            single = not isinstance(part, tuple)
            parts = (part,) if single else part
            if out is None:
                out = tuple(None if x is None else np.empty(np.shape(x)[:-1] + (n_rays,))
                            for x in parts)
            for o, x in zip(out, parts, strict=True):
                if o is not None:
                    o[..., cut] = x
        return out[0] if single else out

    return wrapper


# ----------------------------------------------------------------------------------
# base class


class Hamiltonian:
    """H(q, p) with value and gradient on ray batches; see docs/architecture.md."""

    kind = "custom"
    """"spacetime" (coordinate 0 is time), "medium" (x, y, z optics) or "custom"."""

    def __init__(self, coords: Sequence[str], momenta: Sequence[str], separable: bool = False,
                 parameters: Mapping[str, float] | None = None, time_scale: str | None = None):
        _check_names(coords, momenta)
        self.coords = tuple(coords)
        self.momenta = tuple(momenta)
        self.dim = len(self.coords)
        self.separable = bool(separable)
        self.parameters = checks.check_parameters(parameters)
        self._time_scale = None
        if time_scale is not None:
            self._time_scale = ex.compile_program([time_scale], self.coords, self.parameters)

    # --- to be provided by each model (SoA) ---
    def value_soa(self, Q: np.ndarray, P: np.ndarray) -> np.ndarray:
        """H at each ray, (N,)."""
        raise NotImplementedError

    @blocked
    def gradient_soa(self, Q, P, wrt: str = "qp"):
        """(dH/dq, dH/dp), each (n, N); the half not in ``wrt`` is None."""
        _, dq, dp = self._value_gradient(Q, P, wrt)
        return dq, dp

    @blocked
    def value_gradient_soa(self, Q, P):
        """(H, dH/dq, dH/dp) in one evaluation."""
        return self._value_gradient(Q, P, "qp")

    def _value_gradient(self, Q, P, wrt):
        raise NotImplementedError

    def time_scale_soa(self, Q: np.ndarray):
        """Poincaré time-transformation g(q) and dg/dq (DESIGN.md); default g = 1."""
        n_rays = Q.shape[-1]
        if self._time_scale is None:
            return np.ones(n_rays), np.zeros_like(Q)
        env = {name: Dual.variable(Q[i], i) for i, name in enumerate(self.coords)}
        (g,) = self._time_scale.evaluate(env)
        return _value_and_partials(g, self.dim, n_rays, offset=0)

    def invariants_soa(self, Q, P) -> dict[str, np.ndarray]:
        """Known constants of motion besides H (name -> (N,)); none by default."""
        return {}

    # --- public (N, n) interface ---
    def value(self, q, p) -> np.ndarray:
        """H(q, p) for (N, n) or (n,) arrays: (N,) or a scalar."""
        Q, P, single = self._soa(q, p)
        h = self.value_soa(Q, P)
        return h[0] if single else h

    def gradient(self, q, p):
        """(dH/dq, dH/dp) in the shape of q."""
        Q, P, single = self._soa(q, p)
        dq, dp = self.gradient_soa(Q, P)
        if single:
            return dq[:, 0].copy(), dp[:, 0].copy()
        return dq.T.copy(), dp.T.copy()

    def invariants(self, q, p) -> dict[str, np.ndarray]:
        """Known constants of motion (besides H) for (N, n) or (n,) arrays."""
        Q, P, single = self._soa(q, p)
        inv = self.invariants_soa(Q, P)
        return {k: (v[0] if single else v) for k, v in inv.items()}

    def _soa(self, q, p):
        q = np.asarray(q, dtype=np.float64)
        p = np.asarray(p, dtype=np.float64)
        if q.shape != p.shape or q.shape[-1] != self.dim or q.ndim not in (1, 2):
            raise ValueError(f"q and p must both have shape (N, {self.dim}) or ({self.dim},); "
                             f"got {q.shape} and {p.shape}")
        single = q.ndim == 1
        Q = np.ascontiguousarray(np.atleast_2d(q).T)
        P = np.ascontiguousarray(np.atleast_2d(p).T)
        return Q, P, single

    def __repr__(self) -> str:
        params = ", ".join(f"{k}={v:g}" for k, v in self.parameters.items())
        return f"{type(self).__name__}({', '.join(self.coords)}; {params})"


def _check_names(coords, momenta) -> None:
    names = list(coords) + list(momenta)
    if len(coords) != len(momenta) or not coords:
        raise ValueError("need as many momenta as coordinates, at least one of each")
    bad = [n for n in names if not isinstance(n, str) or not n.isidentifier()]
    if bad:
        raise ValueError(f"variable names must be identifiers: {bad}")
    if len(set(names)) != len(names):
        raise ValueError(f"variable names must be distinct: {names}")
    clash = set(names) & (set(ex.CONSTANTS) | set(ex.dual.FUNCTIONS))
    if clash:
        raise ValueError(f"variable names clash with built-in names: {sorted(clash)}")


def _value_and_partials(result, n: int, n_rays: int, offset: int):
    """Split a Dual (or constant) into its value (N,) and partials rows offset..offset+n."""
    if isinstance(result, Dual):
        value, partials = result.v, result.d
    else:
        value, partials = result, {}
    value = np.broadcast_to(np.asarray(value, dtype=np.float64), (n_rays,))
    grad = np.zeros((n, n_rays))
    for k, g in partials.items():
        if offset <= k < offset + n:
            grad[k - offset] = g
    return value, grad


class FrozenQ:
    """dH/dq at fixed positions Q for any momenta P: the q-dependence evaluated once.

    For H quadratic in p (a metric), an implicit kick P' = P - c dH/dq(Q, P') iterates over
    P' at fixed Q. The model's coefficients and their q-derivatives (dual numbers over q,
    the costly part) are its *form* at Q, computed once; each iterate then costs a few
    products in p. With H0 given, the gradient is that of K = g (H - H0) (Poincaré).
    """

    def __init__(self, apply, form, H0=None):
        self.apply, self.form, self.H0 = apply, form, H0

    def grad_q(self, P: np.ndarray) -> np.ndarray:
        """dH/dq (or dK/dq) at the frozen Q for momenta P, (n, N)."""
        return self.apply(self.form, P, "q", self.H0)[1]

    def subset(self, idx) -> FrozenQ:
        """The same for the rays idx."""
        H0 = self.H0 if self.H0 is None or np.ndim(self.H0) == 0 else self.H0[idx]
        return FrozenQ(self.apply, [dual.subset(x, idx) for x in self.form], H0)


# ----------------------------------------------------------------------------------
# H given as one expression of (q, p)


class ExpressionHamiltonian(Hamiltonian):
    """H given as text over any coordinate and momentum names (any dimension)."""

    def __init__(self, text: str, coords, momenta, parameters=None, definitions=(),
                 time_scale=None, positive: Sequence[str] = ()):
        Hamiltonian.__init__(self, coords, momenta, parameters=parameters, time_scale=time_scale)
        names = self.coords + self.momenta
        self.text = text
        self.program = ex.compile_program([text], names, self.parameters, definitions)
        self.positive = tuple(positive)
        self.separable = _is_separable(text, self.coords, self.momenta, self.parameters,
                                       definitions)
        self.depends_on = self.program.dependencies[0]

    def _env(self, Q, P, wrt: str):
        env = {}
        for i, name in enumerate(self.coords):
            env[name] = Dual.variable(Q[i], i) if "q" in wrt else Q[i]
        for j, name in enumerate(self.momenta):
            env[name] = Dual.variable(P[j], self.dim + j) if "p" in wrt else P[j]
        return env

    def _evaluate(self, Q, P, wrt: str):
        env = self._env(Q, P, wrt)
        (h,) = self.program.evaluate(env)
        bad = self._invalid(env, Q.shape[-1])
        return h, bad

    def _invalid(self, env, n_rays):
        """Rays where a quantity that must be positive (e.g. n) is not: they get NaN."""
        bad = None
        for name in self.positive:
            v = env[name]
            v = v.v if isinstance(v, Dual) else v
            mask = ~(np.asarray(v) > 0)
            bad = mask if bad is None else (bad | mask)
        return None if bad is None else np.broadcast_to(bad, (n_rays,))

    @blocked
    def value_soa(self, Q, P):
        h, bad = self._evaluate(Q, P, "")
        h = np.array(np.broadcast_to(h, (Q.shape[-1],)), dtype=np.float64)
        if bad is not None:
            h[bad] = np.nan
        return h

    def _value_gradient(self, Q, P, wrt):
        h, bad = self._evaluate(Q, P, wrt)
        n_rays = Q.shape[-1]
        value, dq = _value_and_partials(h, self.dim, n_rays, 0)
        _, dp = _value_and_partials(h, self.dim, n_rays, self.dim)
        if bad is not None and bad.any():
            value = value.copy()
            value[bad] = np.nan
            dq[:, bad] = np.nan
            dp[:, bad] = np.nan
        return value, (dq if "q" in wrt else None), (dp if "p" in wrt else None)

    def partials_allocated(self, q, p) -> set[str]:
        """Names of the variables whose partial derivative H's evaluation carries."""
        Q, P, _ = self._soa(q, p)
        h, _ = self._evaluate(Q, P, "qp")
        names = self.coords + self.momenta
        return {names[k] for k in (h.d if isinstance(h, Dual) else {})}


def _is_separable(text, coords, momenta, parameters, definitions) -> bool:
    """True if H is a sum of terms each depending on q alone or on p alone."""
    terms = _additive_terms(text)
    prog = ex.compile_program(terms, tuple(coords) + tuple(momenta), parameters, definitions)
    qs, ps = set(coords), set(momenta)
    return all(dep <= qs or dep <= ps for dep in prog.dependencies)


def _additive_terms(text: str) -> list[str]:
    """Split text at its top-level + and - into terms (signs dropped: they don't matter)."""
    import ast

    tree = ex._parse(text).body
    terms: list[ast.AST] = []

    def walk(node):
        if isinstance(node, ast.BinOp) and isinstance(node.op, (ast.Add, ast.Sub)):
            walk(node.left)
            walk(node.right)
        elif isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
            walk(node.operand)
        else:
            terms.append(node)

    walk(tree)
    return [ast.unparse(t) for t in terms]


def from_expression(text: str, q: Sequence[str], p: Sequence[str],
                    parameters: Mapping[str, float] | None = None,
                    definitions: Mapping[str, str] | Sequence[tuple[str, str]] = (),
                    time_scale: str | None = None) -> ExpressionHamiltonian:
    """H from text over coordinates ``q`` and momenta ``p`` (any names, any dimension)."""
    return ExpressionHamiltonian(text, q, p, parameters, definitions, time_scale)


# ----------------------------------------------------------------------------------
# metric Hamiltonians H = 1/2 g^ij(q) p_i p_j  (seed Eq. 10)


class MetricHamiltonian(Hamiltonian):
    """H = 1/2 g^ij(q) p_i p_j for an inverse metric given entry by entry."""

    kind = "spacetime"

    def __init__(self, inverse: Sequence[Sequence[str]], coords: Sequence[str],
                 momenta: Sequence[str] | None = None, parameters=None, definitions=(),
                 time_scale: str | None = None, symmetric_check: bool = True):
        momenta = tuple(momenta) if momenta is not None else tuple(f"p_{c}" for c in coords)
        Hamiltonian.__init__(self, coords, momenta, parameters=parameters, time_scale=time_scale)
        n = self.dim
        entries = [[str(e).strip() for e in row] for row in inverse]
        if len(entries) != n or any(len(row) != n for row in entries):
            raise ValueError(f"inverse metric must be {n}x{n} for coordinates {self.coords}")
        if symmetric_check:
            for i in range(n):
                for j in range(i):
                    if entries[i][j] != entries[j][i] and entries[j][i] not in ("", "0"):
                        raise ValueError(f"inverse metric must be symmetric: g^{i}{j} "
                                         f"'{entries[i][j]}' != g^{j}{i} '{entries[j][i]}'")
        pairs, texts = [], []
        for i in range(n):
            for j in range(i, n):
                text = entries[i][j] or entries[j][i] or "0"
                pairs.append((i, j))
                texts.append(text)
        self.program = ex.compile_program(texts, self.coords, self.parameters, definitions)
        keep = [k for k, o in enumerate(self.program.outputs) if o.constant != 0.0]
        self.pairs = [pairs[k] for k in keep]
        self._outputs = keep
        self.separable = all(not self.program.dependencies[k] for k in keep)

    def inverse_metric_soa(self, Q, seed: bool):
        """Entries g^ij (i <= j) that are not identically zero, as values or Duals over q."""
        env = {name: (Dual.variable(Q[i], i) if seed else Q[i])
               for i, name in enumerate(self.coords)}
        values = self.program.evaluate(env)
        return [values[k] for k in self._outputs]

    def _form(self, Q, seed: bool, scaled: bool = False):
        """[*entries g^ij, time scale g(q) or None]: values, or Duals over q if seed."""
        entries = self.inverse_metric_soa(Q, seed)
        scale = None
        if scaled and self._time_scale is not None:
            env = {name: (Dual.variable(Q[i], i) if seed else Q[i])
                   for i, name in enumerate(self.coords)}
            (scale,) = self._time_scale.evaluate(env)
        return [*entries, scale]

    def _apply(self, form, P, want: str, H0=None):
        """(H, dH/dq, dH/dp) from a form, each None unless wanted ("v", "q", "p" in want).

        With H0: K = g (H - H0) and its gradient instead (g: the form's time scale, or 1).
        """
        entries, scale = form[:-1], form[-1]
        n, n_rays = self.dim, P.shape[-1]
        need_q, need_p = "q" in want, "p" in want
        need_h = "v" in want or (need_q and H0 is not None and isinstance(scale, Dual))
        h = np.zeros(n_rays) if need_h else None
        dq = np.zeros((n, n_rays)) if need_q else None
        dp = np.zeros((n, n_rays)) if need_p else None
        for (i, j), g in zip(self.pairs, entries, strict=True):
            w = 0.5 if i == j else 1.0
            gv = g.v if isinstance(g, Dual) else g
            if need_h or need_q:
                pipj = P[i] * P[j]
            if need_h:
                h += w * gv * pipj
            if need_p:
                dp[i] += gv * P[j]
                if i != j:
                    dp[j] += gv * P[i]
            if need_q and isinstance(g, Dual):
                wp = w * pipj
                for k, dg in g.d.items():
                    dq[k] += dg * wp
        if H0 is None:
            return h, dq, dp
        dh = None if h is None else h - H0
        if scale is None:
            return dh, dq, dp
        sv = scale.v if isinstance(scale, Dual) else scale
        if need_p:
            dp *= sv
        if need_q:
            dq *= sv
            for k, dg in (scale.d.items() if isinstance(scale, Dual) else ()):
                dq[k] += dg * dh
        return (None if dh is None else sv * dh), dq, dp

    @blocked
    def value_soa(self, Q, P):
        n_rays = Q.shape[-1]
        h = np.zeros(n_rays)
        for (i, j), g in zip(self.pairs, self.inverse_metric_soa(Q, seed=False), strict=True):
            w = 0.5 if i == j else 1.0
            h += w * g * P[i] * P[j]
        return h

    def _value_gradient(self, Q, P, wrt):
        return self._apply(self._form(Q, "q" in wrt), P, "v" + wrt)

    @blocked
    def poincare_soa(self, Q, P, H0, wrt: str = "qp"):
        """(K = g (H - H0), dK/dq, dK/dp) in one evaluation: the derivatives not in wrt are
        None, and so is K when only dK/dp is asked for."""
        return self._apply(self._form(Q, "q" in wrt, scaled=True), P,
                           wrt if wrt == "p" else "v" + wrt, H0)

    def frozen_q(self, Q, H0=None) -> FrozenQ:
        """dH/dq at Q for any momenta (dK/dq of K = g (H - H0) with H0), see FrozenQ."""
        return FrozenQ(self._apply, self._form(Q, True, scaled=H0 is not None), H0)

    def partials_allocated(self, q, p) -> set[str]:
        """Coordinates whose partial derivative the metric's evaluation carries."""
        Q, _, _ = self._soa(q, p)
        keys = set()
        for g in self.inverse_metric_soa(Q, seed=True):
            if isinstance(g, Dual):
                keys |= set(g.d)
        return {self.coords[k] for k in keys}


def metric(inverse: Sequence[Sequence[str]], coords: Sequence[str] = ("t", "x", "y", "z"),
           momenta: Sequence[str] | None = None, parameters: Mapping[str, float] | None = None,
           definitions: Mapping[str, str] | Sequence[tuple[str, str]] = (),
           time_scale: str | None = None) -> MetricHamiltonian:
    """Photon Hamiltonian H = 1/2 g^ij p_i p_j of any inverse metric (seed Eq. 10)."""
    return MetricHamiltonian(inverse, coords, momenta, parameters, definitions, time_scale)


# ----------------------------------------------------------------------------------
# named models


def _check_rg(rg: float) -> float:
    return checks.check_positive("rg (Schwarzschild radius)", rg)


def _check_spin(rg: float, a: float) -> float:
    a = checks.check_range("a (Kerr spin)", a)
    if abs(a) > rg / 2:
        raise ValueError(f"Kerr spin a = {a} is beyond extremal: need |a| <= rg/2 = M = {rg / 2}"
                         f" (a/M = {2 * a / rg:.4g})")
    return a


class SphericalSpacetime(MetricHamiltonian):
    """A metric in (t, r, theta, phi) Boyer–Lindquist-like coordinates around a mass."""

    chart = "spherical"

    def __init__(self, inverse, rg, a, time_scale, definitions=(), horizon=0.0):
        coords = ("t", "r", "theta", "phi")
        super().__init__(inverse, coords, ("p_t", "p_r", "p_theta", "p_phi"),
                         parameters={"rg": rg, "a": a}, definitions=definitions,
                         time_scale=time_scale)
        self.rg, self.a = rg, a
        self.horizon = horizon

    def captured_soa(self, Q) -> np.ndarray:
        """Rays at r < 1.01 r+ (N,): the Poincaré step only reaches r+ asymptotically here,
        and an ingoing photon that close to the horizon cannot come back out."""
        return Q[1] < 1.01 * self.horizon if self.horizon > 0 else np.zeros(Q.shape[1], bool)

    def invariants_soa(self, Q, P):
        """E = -p_t, L = p_phi and the Carter constant (photons, mu = 0)."""
        if self.rg == 0.0:
            return {"p_t": P[0].copy(), "p_phi": P[3].copy()}
        cos2 = np.cos(Q[2]) ** 2
        sin2 = 1.0 - cos2
        carter = P[2] ** 2 + cos2 * (-(self.a ** 2) * P[0] ** 2 + P[3] ** 2 / sin2)
        return {"p_t": P[0].copy(), "p_phi": P[3].copy(), "carter": carter}


def minkowski(chart: str = "cartesian") -> MetricHamiltonian:
    """Flat spacetime: Cartesian (seed Eq. 13) or spherical (seed Eq. 14) coordinates."""
    if chart == "cartesian":
        h = MetricHamiltonian([["-1", "0", "0", "0"], ["0", "1", "0", "0"],
                               ["0", "0", "1", "0"], ["0", "0", "0", "1"]],
                              ("t", "x", "y", "z"), ("p_t", "p_x", "p_y", "p_z"))
        h.chart = "cartesian"
        h.rg, h.a, h.horizon = 0.0, 0.0, 0.0
        return h
    if chart == "spherical":
        inv = [["-1", "0", "0", "0"], ["0", "1", "0", "0"],
               ["0", "0", "1/r**2", "0"], ["0", "0", "0", "1/(r**2*sin(theta)**2)"]]
        return SphericalSpacetime(inv, 0.0, 0.0, time_scale=None)
    raise ValueError(f"unknown chart '{chart}' for minkowski (use 'cartesian' or 'spherical')")


def schwarzschild(rg: float = 1.0) -> SphericalSpacetime:
    """Schwarzschild black hole in (t, r, theta, phi) (seed Eq. 9/15, with the p_phi term)."""
    rg = _check_rg(rg)
    inv = [["-1/(1 - rg/r)", "0", "0", "0"], ["0", "1 - rg/r", "0", "0"],
           ["0", "0", "1/r**2", "0"], ["0", "0", "0", "1/(r**2*sin(theta)**2)"]]
    return SphericalSpacetime(inv, rg, 0.0, time_scale="r - rg", horizon=rg)


def kerr(rg: float = 1.0, a: float = 0.0, chart: str = "boyer_lindquist",
         outgoing: bool = False) -> MetricHamiltonian:
    """Kerr black hole, spin length a = J/M with |a| <= M = rg/2 (seed Eq. 12).

    ``chart="boyer_lindquist"``: (t, r, theta, phi). ``chart="kerr_schild"``: Cartesian
    (t, x, y, z), horizon-penetrating, no coordinate pole (DESIGN.md formula); ingoing
    (regular on the future horizon) unless ``outgoing=True`` (regular on the past one).
    """
    rg = _check_rg(rg)
    a = _check_spin(rg, a)
    m = rg / 2
    horizon = m + math.sqrt(max(m * m - a * a, 0.0))
    if chart == "boyer_lindquist":
        defs = [("s2", "sin(theta)**2"), ("sigma", "r**2 + a**2*(1 - s2)"),
                ("delta", "r**2 - rg*r + a**2"), ("sd", "sigma*delta")]
        inv = [["-((r**2 + a**2)**2 - a**2*delta*s2)/sd", "0", "0", "-rg*a*r/sd"],
               ["0", "delta/sigma", "0", "0"],
               ["0", "0", "1/sigma", "0"],
               ["-rg*a*r/sd", "0", "0", "(delta - a**2*s2)/(sd*s2)"]]
        h = SphericalSpacetime(inv, rg, a, time_scale="(r**2 - rg*r + a**2)/r",
                               definitions=defs, horizon=horizon)
        return h
    if chart == "kerr_schild":
        return KerrSchild(rg, a, horizon, outgoing)
    raise ValueError(f"unknown chart '{chart}' for kerr (use 'boyer_lindquist' or 'kerr_schild')")


class KerrSchild(ExpressionHamiltonian):
    """Kerr in Cartesian Kerr–Schild coordinates: g^uv = eta^uv - f l^u l^v (DESIGN.md).

    H is kept as text (``self.program``, the definition), but evaluated in its Kerr–Schild
    form H = 1/2 eta^uv p_u p_v - 1/2 f (k.p)^2, where l.p = k(q).p is linear in p: f, the
    k_i and r are dual numbers over (x, y, z) only (t is cyclic; no momentum seeds), and
    dH/dp = eta p - f (k.p) k,  dH/dq = -1/2 (k.p)^2 df - f (k.p) p_i dk_i.
    The Poincaré time scale g = r comes out of the same evaluation.
    """

    kind = "spacetime"
    chart = "kerr_schild"

    def __init__(self, rg: float, a: float, horizon: float, outgoing: bool = False):
        # ingoing: l_mu = (1, l_i(a)), regular on the future horizon; outgoing: the time
        # reverse of ingoing with spin -a, l_mu = (-1, l_i(-a)), regular on the past horizon
        # (the one rays traced backwards from a camera cross).
        s = "-" if outgoing else "+"
        o = "+" if outgoing else "-"
        k = [f"(r*x {s} a*y)/ra2", f"(r*y {o} a*x)/ra2", "z/r"]
        lp = f"{'' if outgoing else '-'}p_t + ({k[0]})*p_x + ({k[1]})*p_y + ({k[2]})*p_z"
        defs = [("rho2", "x**2 + y**2 + z**2 - a**2"),
                ("r2", "0.5*(rho2 + sqrt(rho2**2 + 4*a**2*z**2))"), ("r", "sqrt(r2)"),
                ("f", "rg*r*r2/(r2**2 + a**2*z**2)"), ("ra2", "r2 + a**2")]
        text = "0.5*(-p_t**2 + p_x**2 + p_y**2 + p_z**2 - f*lp**2)"
        super().__init__(text, ("t", "x", "y", "z"), ("p_t", "p_x", "p_y", "p_z"),
                         parameters={"rg": rg, "a": a}, definitions=defs + [("lp", lp)],
                         time_scale="sqrt(0.5*(x**2 + y**2 + z**2 - a**2 + "
                                    "sqrt((x**2 + y**2 + z**2 - a**2)**2 + 4*a**2*z**2)))")
        self.rg, self.a, self.horizon = rg, a, horizon
        self.outgoing = outgoing
        self._k_t = 1.0 if outgoing else -1.0

    def for_backward_tracing(self) -> KerrSchild:
        """The outgoing chart: rays followed into the past cross the past horizon smoothly."""
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
        dr = (x * c, y * c, z * (ra2 / (r * D)))            # dr/dx, dr/dy, dr/dz
        # df_i = f (3 dr_i / r - dW_i / W), dW_i = 4 r^3 dr_i + 2 a^2 z [i = z]
        u = (3.0 / r - 4.0 * r * r2 / W) * f
        df = [u * dr[0], u * dr[1], u * dr[2] - (2.0 * a2 / W) * z * f]
        # dk_j/dx_i = (d numerator_j / dx_i - k_j 2 r dr_i) / ra2
        two_r = 2.0 * r
        dkx = [(dr[0] * x + r - kx * two_r * dr[0]) * inv_ra2,
               (dr[1] * x + sa - kx * two_r * dr[1]) * inv_ra2,
               (dr[2] * x - kx * two_r * dr[2]) * inv_ra2]
        dky = [(dr[0] * y - sa - ky * two_r * dr[0]) * inv_ra2,
               (dr[1] * y + r - ky * two_r * dr[1]) * inv_ra2,
               (dr[2] * y - ky * two_r * dr[2]) * inv_ra2]
        kz_r = kz / r
        dkz = [-kz_r * dr[0], -kz_r * dr[1], 1.0 / r - kz_r * dr[2]]
        return [Dual(v, {1: d[0], 2: d[1], 3: d[2]})
                for v, d in ((f, df), (kx, dkx), (ky, dky), (kz, dkz), (r, dr))]

    def _apply(self, form, P, want: str, H0=None):
        """(H, dH/dq, dH/dp) from the form [f, k_x, k_y, k_z, r], each None unless wanted
        ("v", "q", "p" in want). With H0: K = r (H - H0) and its gradient instead."""
        need_q = "q" in want
        if need_q:
            (f, df), (kx, dkx), (ky, dky), (kz, dkz), (r, dr) = (
                (d.v, d.d) for d in form)
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
        return np.array(r.v), dr

    @blocked
    def poincare_soa(self, Q, P, H0, wrt: str = "qp"):
        """(K = r (H - H0), dK/dq, dK/dp) in one evaluation: the derivatives not in wrt are
        None, and so is K when only dK/dp is asked for."""
        return self._apply(self._form_soa(Q, "q" in wrt), P, wrt if wrt == "p" else "v" + wrt,
                           H0)

    def frozen_q(self, Q, H0=None) -> FrozenQ:
        """dH/dq at Q for any momenta (dK/dq of K = r (H - H0) with H0), see FrozenQ."""
        return FrozenQ(self._apply, self._form_soa(Q, True), H0)

    def radius_soa(self, Q):
        """Kerr–Schild r > 0 from r^4 - (x^2+y^2+z^2-a^2) r^2 - a^2 z^2 = 0."""
        x, y, z = Q[1], Q[2], Q[3]
        rho2 = x * x + y * y + z * z - self.a ** 2
        return np.sqrt(0.5 * (rho2 + np.sqrt(rho2 * rho2 + 4 * self.a ** 2 * z * z)))

    def captured_soa(self, Q) -> np.ndarray:
        """Rays inside the outer horizon, r < r+ (N,)."""
        return self.radius_soa(Q) < self.horizon

    def invariants_soa(self, Q, P):
        """E = -p_t and L_z = x p_y - y p_x."""
        return {"p_t": P[0].copy(), "L_z": Q[1] * P[2] - Q[2] * P[1]}


class Medium(ExpressionHamiltonian):
    """Light in a medium of refractive index n(x, y, z) (optical Hamiltonian)."""

    kind = "medium"

    def __init__(self, index: str, literal: bool, parameters=None, bounds=None):
        coords, momenta = ("x", "y", "z"), ("p_x", "p_y", "p_z")
        text = "0.5*n*(p_x**2 + p_y**2 + p_z**2)" if literal else \
            "0.5*(p_x**2 + p_y**2 + p_z**2)/n**2"
        super().__init__(text, coords, momenta, parameters, definitions=[("n", index)],
                         positive=("n",))
        self.index_text = index
        self.literal = literal
        self.bounds = checks.check_box("medium bounds", bounds)
        self._index = ex.compile_expression(index, coords, parameters)

    def index_soa(self, Q) -> np.ndarray:
        """The refractive index (the user's n, or the seed's literal n) at positions (3, N)."""
        n = self._index({"x": Q[0], "y": Q[1], "z": Q[2]})
        return np.broadcast_to(np.asarray(n, dtype=np.float64), (Q.shape[-1],))

    def check_index(self, points) -> None:
        """Raise ValueError if n is not a positive finite number at the given (N, 3) points."""
        pts = np.atleast_2d(np.asarray(points, dtype=np.float64))
        with np.errstate(all="ignore"):
            n = self.index_soa(pts.T)
        bad = ~(np.isfinite(n) & (n > 0))
        if bad.any():
            where = pts[np.argmax(bad)]
            raise ValueError(f"refractive index '{self.index_text}' is {n[np.argmax(bad)]:g} at "
                             f"(x, y, z) = ({where[0]:g}, {where[1]:g}, {where[2]:g}); "
                             "it must be positive")


def medium(index: str, literal: bool = False, parameters: Mapping[str, float] | None = None,
           bounds=None) -> Medium:
    """Optical medium of refractive index n(x, y, z) given as text.

    Default: the physical optical Hamiltonian H = |p|^2 / (2 n^2), whose rays obey
    Eq. 4 (rays are geodesics of n^2 delta_ij). ``literal=True``: the seed's Eq. 8/16,
    H = n |p|^2 / 2, which gives the same rays if its n is read as 1/n^2; use it to
    reproduce the seed's Eq. 17/18 figures as printed. ``bounds`` = (lo, hi) corners of
    the box outside which the medium is uniform (rays travel straight there).
    """
    return Medium(index, literal, parameters, bounds)
