"""The model base class: :class:`Hamiltonian` and the block-by-block evaluation of big batches.

Internally arrays are structure-of-arrays with rays on the last axis (``Q``, ``P`` of
shape ``(n, N)``); the public ``value`` and ``gradient`` take the contract's ``(N, n)`` or
``(n,)`` arrays. Partial derivatives come from :mod:`core.dual`.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from .. import checks
from .. import expressions as ex
from ..backend import array_module, is_array
from ..charts import CartesianChart, Chart
from ..dual import Dual
from ..integrators.system import System

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
            part = method(
                self,
                Q[..., cut],
                *(
                    a[..., cut] if is_array(a) and a.ndim and a.shape[-1] == n_rays else a
                    for a in args
                ),
                **kwargs,
            )
            single = not isinstance(part, tuple)
            parts = (part,) if single else part
            if out is None:
                out = tuple(
                    None if x is None else np.empty_like(x, shape=x.shape[:-1] + (n_rays,))
                    for x in parts
                )
            for o, x in zip(out, parts, strict=True):
                if o is not None:
                    o[..., cut] = x
        assert out is not None
        return out[0] if single else out

    return wrapper


class Hamiltonian(System):
    """H(q, p) with value and gradient on ray batches; see docs/architecture.md.

    What the integrators need is :class:`core.integrators.System`; what the tracer reads
    of a model is below (class defaults: no mass, no horizon, unbounded, no split).
    """

    kind = "custom"
    """"spacetime" (coordinate 0 is time), "medium" (x, y, z optics) or "custom"."""
    flat = False
    """True where nothing bends light: the tracer draws straight rays, no integration."""
    rg = 0.0
    """Schwarzschild radius 2M of the mass at the origin (0: none); sets the far field,
    the region around the mass and the step rule."""
    a = 0.0
    """Spin length J/M of the mass (the spheroidal chart's a)."""
    horizon = 0.0
    """Outer horizon radius r+ in the model's radial coordinate (0: none)."""
    bounds: tuple[np.ndarray, np.ndarray] | None = None
    """(lo, hi) of the box outside which the model is uniform (rays straight); None."""

    def __init__(
        self,
        coords: Sequence[str],
        momenta: Sequence[str],
        separable: bool = False,
        parameters: Mapping[str, float] | None = None,
        time_scale: str | None = None,
    ):
        _check_names(coords, momenta)
        self.coords = tuple(coords)
        self.momenta = tuple(momenta)
        self.dim = len(self.coords)
        self.separable = bool(separable)
        self.parameters = checks.check_parameters(parameters)
        self._time_scale: ex.Program | None = None
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

    @property
    def mass(self) -> float:
        """M = rg / 2."""
        return 0.5 * float(self.rg)

    @property
    def scales_time(self) -> bool:
        """Whether the model has a Poincaré time scale g(q) other than 1."""
        return self._time_scale is not None

    @property
    def spherical(self) -> bool:
        """Whether turning a ray about any axis through the model's centre turns its whole
        path with it: the model, its chart, its flows and its far field are symmetric under
        rotations (core/tracing/differentials.py carries one ray differential instead of
        two)."""
        return False

    @property
    def chart(self) -> Chart:
        """The chart its coordinates are written in (core.charts): Cartesian (t, x, y, z) for
        a spacetime, (x, y, z) otherwise, unless a model writes them in another."""
        if self.kind == "spacetime":
            if self.dim != 4:
                raise ValueError(
                    f"a spacetime model needs 4 coordinates (t, x, y, z), got {self.dim}"
                )
            return CartesianChart(time_index=0)
        if self.dim != 3:
            raise ValueError(
                f"to render, a model needs coordinates (x, y, z) or (t, x, y, z); got {self.coords}"
            )
        return CartesianChart(time_index=None)

    def kerr_orbits(self) -> tuple[float, float] | None:
        """(M, a) where light and gas orbit as around a Kerr hole of mass M and spin length a
        (Schwarzschild: a = 0), in the equatorial plane of this model's frame: an accretion
        disk's innermost stable orbit and Keplerian speed (core.geometry.disk) follow from
        them. None: no disk can orbit here (flat space, media, other metrics)."""
        return None

    def ray_capture_test(self) -> Callable[[np.ndarray, np.ndarray], np.ndarray] | None:
        """The tracer's capture test, (Q, P) -> (N,) bool: rays that can no longer come out
        of a horizon. By default ``capture_test()`` on Q alone (None: no horizon); a model
        whose capture depends on the ray's direction says so (Kerr's split form)."""
        captured = self.capture_test()
        if captured is None:
            return None
        return lambda Q, P: captured(Q)

    @property
    def has_kinks(self) -> bool:
        """Whether its force has kinks (``kinks_soa``): none by default."""
        return False

    def kinks_soa(self, Q: np.ndarray, derivatives: bool = False) -> Any:
        """(K, N) values at positions (3, N) of the K expressions whose sign change is a kink
        in the force (with ``derivatives``, also their gradients (K, 3, N)): the tracer
        splits a step where a ray crosses one. None: smooth everywhere (the default)."""
        return None

    def face_jump(self, X: np.ndarray) -> np.ndarray:
        """(N,) whether light meets an interface at points (3, N) of the faces of its box
        (``bounds``): a medium whose index there differs from the vacuum outside. None by
        default."""
        return np.zeros_like(X[0], dtype=bool)

    def check_faces(self, points: np.ndarray) -> None:
        """ValueError where every one of ``points`` (3, N) on the box's faces is an
        interface (``face_jump``); nothing by default."""

    def for_backward_tracing(self, explicit_split: bool = False) -> Hamiltonian:
        """The same light rays in the chart the tracer follows them in (regular where rays
        followed into the past go); the model itself unless a better chart exists. With
        ``explicit_split``: a form whose split_parts an explicit splitting can take, where
        there is one (Schwarzschild: its isotropic optical medium)."""
        return self

    def radius_at(self, X: np.ndarray) -> np.ndarray:
        """The radial coordinate that ``horizon`` is measured in, at local Cartesian
        positions X (3, N): the distance from the centre unless a model says otherwise."""
        return np.sqrt(np.einsum("ij,ij->j", X, X))

    def time_scale_soa(self, Q: np.ndarray):
        """Poincaré time-transformation g(q) and dg/dq (docs/design.md); default g = 1."""
        if self._time_scale is None:
            return np.ones_like(Q[0]), np.zeros_like(Q)
        env: dict[str, object] = {
            name: Dual.variable(Q[i], i) for i, name in enumerate(self.coords)
        }
        (g,) = self._time_scale.evaluate(env)
        return _value_and_partials(g, self.dim, Q, offset=0)

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
            raise ValueError(
                f"q and p must both have shape (N, {self.dim}) or ({self.dim},); "
                f"got {q.shape} and {p.shape}"
            )
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


def _value_and_partials(result, n: int, like: Any, offset: int):
    """Split a Dual (or constant) into its value (N,) and partials rows offset..offset+n,
    arrays of ``like``'s library (the rays' coordinates (..., N))."""
    if isinstance(result, Dual):
        value, partials = result.v, result.d
    else:
        value, partials = result, {}
    n_rays, xp = like.shape[-1], array_module(like)
    value = xp.broadcast_to(xp.asarray(value, dtype=np.float64), (n_rays,))
    grad = xp.zeros((n, n_rays))
    for k, g in partials.items():
        if offset <= k < offset + n:
            grad[k - offset] = g
    return value, grad
