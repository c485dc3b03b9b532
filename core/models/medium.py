"""Light in a medium of refractive index n(x, y, z): the optical Hamiltonian."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from .. import checks
from .. import expressions as ex
from ..backend import array_module
from ..dual import Dual
from .base import _value_and_partials
from .expression import ExpressionHamiltonian
from .medium_split import OpticalSplit

FACE_JUMP = 5e-3
"""A medium's box holds all of its index's variation: outside it light travels straight in
vacuum (n = 1). Where the physical index at the box's faces differs from 1 by more than
FACE_JUMP (relative) the box cuts an interface the medium does not declare: a ray leaving
there is failed (``face_jump``), and a box whose faces jump everywhere is refused before
tracing (``check_faces``). Below it the jump is taken as none: the seed's mirages, whose
air is 1.002-1.003 at their boxes' tops (their layers' own contrast), render as before."""
FACE_SAMPLES = 16
"""``check_faces`` reads the index on a FACE_SAMPLES x FACE_SAMPLES grid on each face."""


class Medium(ExpressionHamiltonian):
    """Light in a medium of refractive index n(x, y, z) (optical Hamiltonian)."""

    kind = "medium"

    def __init__(self, index: str, literal: bool, parameters=None, bounds=None):
        coords, momenta = ("x", "y", "z"), ("p_x", "p_y", "p_z")
        text = (
            "0.5*n*(p_x**2 + p_y**2 + p_z**2)" if literal else "0.5*(p_x**2 + p_y**2 + p_z**2)/n**2"
        )
        super().__init__(
            text, coords, momenta, parameters, definitions=[("n", index)], positive=("n",)
        )
        self.index_text = index
        self.literal = literal
        self.bounds = checks.check_box("medium bounds", bounds)
        self._index = ex.compile_expression(index, coords, parameters)
        self._index_program = ex.compile_program([index], coords, self.parameters)
        kinks = ex.kink_arguments(index)
        self._kinks = ex.compile_program(kinks, coords, self.parameters) if kinks else None

    def split_weight_soa(self, Q, derivatives: bool = True):
        """w(q) of the explicit split and its gradient (3, N) (None if not asked for):
        w = n^2 (physical H, Poincaré g = n^2) or 1/n (literal H, g = 1/n); NaN where n <= 0.
        """
        env: dict[str, object] = {
            name: (Dual.variable(Q[i], i) if derivatives else Q[i])
            for i, name in enumerate(self.coords)
        }
        (n,) = self._index_program.evaluate(env)
        n, dn = _value_and_partials(n, 3, Q, offset=0)
        with np.errstate(all="ignore"):
            n = np.where(n > 0, n, np.nan)
            if self.literal:
                w, dw_dn = 1.0 / n, -1.0 / (n * n)
            else:
                w, dw_dn = n * n, 2.0 * n
        return w, (dw_dn * dn if derivatives else None)

    def time_scale_soa(self, Q):
        """Poincaré g = w (n^2, literal: 1/n), which makes K = g (H - H0) separable."""
        w, dw = self.split_weight_soa(Q)
        return w, dw

    def split_parts(self, H0=0.0, clocked: bool = False) -> OpticalSplit:
        """The explicit split K = |p|^2/2 - H0 w(q) (core/models/medium_split.py)."""
        return OpticalSplit(self, H0, clocked)

    def index_soa(self, Q) -> np.ndarray:
        """The refractive index (the user's n, or the seed's literal n) at positions (3, N)."""
        n = self._index({"x": Q[0], "y": Q[1], "z": Q[2]})
        xp = array_module(Q)
        return xp.broadcast_to(xp.asarray(n, dtype=np.float64), (Q.shape[-1],))

    @property
    def has_kinks(self) -> bool:
        """Whether n has kinks: an abs(...) in its expression."""
        return self._kinks is not None

    def kinks_soa(self, Q, derivatives: bool = False):
        """(K, N) the values at positions (3, N) of the K expressions whose sign change is a
        kink in n (the arguments of its abs(...)): where a ray crosses one, the tracer
        splits its step there (core.tracing.stepping.Stepper.advance); with
        ``derivatives``, also their gradients (K, 3, N). None: n is smooth."""
        if self._kinks is None:
            return None
        env: dict[str, object] = {
            name: (Dual.variable(Q[i], i) if derivatives else Q[i])
            for i, name in enumerate(self.coords)
        }
        parts = [_value_and_partials(f, 3, Q, 0) for f in self._kinks.evaluate(env)]
        values = np.stack([v for v, _ in parts])
        return (values, np.stack([g for _, g in parts])) if derivatives else values

    def physical_index_soa(self, Q) -> np.ndarray:
        """The physical refractive index at positions (3, N) (literal form: n^(-1/2))."""
        n = self.index_soa(Q)
        with np.errstate(all="ignore"):
            return 1.0 / np.sqrt(n) if self.literal else n

    def face_jump(self, Q) -> np.ndarray:
        """(N,) whether the index jumps at the box's faces at positions (3, N): the physical
        index differs from the vacuum outside by more than FACE_JUMP (or is not finite)."""
        n = self.physical_index_soa(Q)
        with np.errstate(all="ignore"):
            return ~(np.abs(n - 1.0) <= FACE_JUMP)

    def check_faces(self, points) -> None:
        """ValueError naming the jump where the index jumps (``face_jump``) at every one of
        ``points`` (3, N) on the box's faces: every ray would leave through an interface
        the box cuts (a Maxwell fish-eye 2/(1 + r^2/4) in a box of +-3: n 0.26-0.62 there)."""
        jumps = self.face_jump(points)
        if not jumps.all():
            return
        with np.errstate(all="ignore"):
            n = self.physical_index_soa(points)
        lo, hi = np.nanmin(n), np.nanmax(n)
        raise ValueError(
            f"refractive index '{self.index_text}' jumps at the medium's box: its physical "
            f"index on the box's faces is {lo:.3g} to {hi:.3g}, but outside the box light "
            "travels in vacuum (n = 1), and the box cuts an interface the medium does not "
            "have; make n reach 1 at the box (e.g. n = 1 outside a lens's radius, written "
            "with abs) or enlarge the box to where it does"
        )

    def check_index(self, points) -> None:
        """Raise ValueError if n is not a positive finite number at the given (N, 3) points."""
        pts = np.atleast_2d(np.asarray(points, dtype=np.float64))
        with np.errstate(all="ignore"):
            n = self.index_soa(pts.T)
        bad = ~(np.isfinite(n) & (n > 0))
        if bad.any():
            where = pts[np.argmax(bad)]
            raise ValueError(
                f"refractive index '{self.index_text}' is {n[np.argmax(bad)]:g} at "
                f"(x, y, z) = ({where[0]:g}, {where[1]:g}, {where[2]:g}); "
                "it must be positive"
            )


def medium(
    index: str, literal: bool = False, parameters: Mapping[str, float] | None = None, bounds=None
) -> Medium:
    """Optical medium of refractive index n(x, y, z) given as text.

    Default: the physical optical Hamiltonian H = |p|^2 / (2 n^2), whose rays obey
    Eq. 4 (rays are geodesics of n^2 delta_ij). ``literal=True``: the seed's Eq. 8/16,
    H = n |p|^2 / 2, which gives the same rays if its n is read as 1/n^2; use it to
    reproduce the seed's Eq. 17/18 figures as printed. ``bounds`` = (lo, hi) corners of
    the box outside which the medium is uniform (rays travel straight there).
    """
    return Medium(index, literal, parameters, bounds)
