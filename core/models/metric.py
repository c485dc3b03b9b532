"""Metric Hamiltonians H = 1/2 g^ij(q) p_i p_j for any inverse metric (seed Eq. 10)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from .. import expressions as ex
from ..backend import array_module
from ..dual import Dual
from ..integrators.system import FrozenQ
from .base import Hamiltonian, blocked


class MetricHamiltonian(Hamiltonian):
    """H = 1/2 g^ij(q) p_i p_j for an inverse metric given entry by entry."""

    kind = "spacetime"

    def __init__(
        self,
        inverse: Sequence[Sequence[str]],
        coords: Sequence[str],
        momenta: Sequence[str] | None = None,
        parameters=None,
        definitions=(),
        time_scale: str | None = None,
        symmetric_check: bool = True,
    ):
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
                        raise ValueError(
                            f"inverse metric must be symmetric: g^{i}{j} "
                            f"'{entries[i][j]}' != g^{j}{i} '{entries[j][i]}'"
                        )
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
        env = {
            name: (Dual.variable(Q[i], i) if seed else Q[i]) for i, name in enumerate(self.coords)
        }
        values = self.program.evaluate(env)
        return [values[k] for k in self._outputs]

    def _form(self, Q, seed: bool, scaled: bool = False):
        """[*entries g^ij, time scale g(q) or None]: values, or Duals over q if seed."""
        entries = self.inverse_metric_soa(Q, seed)
        scale = None
        if scaled and self._time_scale is not None:
            env = {
                name: (Dual.variable(Q[i], i) if seed else Q[i])
                for i, name in enumerate(self.coords)
            }
            (scale,) = self._time_scale.evaluate(env)
        return [*entries, scale]

    # noqa: C901 below: one fused pass for every combination of H, dH/dq, dH/dp and K over
    # the metric's entries (the render's hot path: each entry is read once)
    def _apply(self, form, P, want: str, H0=None):  # noqa: C901
        """(H, dH/dq, dH/dp) from a form, each None unless wanted ("v", "q", "p" in want).

        With H0: K = g (H - H0) and its gradient instead (g: the form's time scale, or 1).
        """
        entries, scale = form[:-1], form[-1]
        n, n_rays = self.dim, P.shape[-1]
        need_q, need_p = "q" in want, "p" in want
        need_h = "v" in want or (need_q and H0 is not None and isinstance(scale, Dual))
        # (Any: each is an array exactly where it is wanted, None elsewhere)
        xp = array_module(P)
        h: Any = xp.zeros(n_rays) if need_h else None
        dq: Any = xp.zeros((n, n_rays)) if need_q else None
        dp: Any = xp.zeros((n, n_rays)) if need_p else None
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
        dh: Any = None if h is None else h - H0
        if scale is None:
            return dh, dq, dp
        sv: Any = scale.v if isinstance(scale, Dual) else scale
        if need_p:
            dp *= sv
        if need_q:
            dq *= sv
            for k, dg in scale.d.items() if isinstance(scale, Dual) else ():
                dq[k] += dg * dh
        return (None if dh is None else sv * dh), dq, dp

    @blocked
    def value_soa(self, Q, P):
        h = np.zeros_like(P[0])
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
        return self._apply(
            self._form(Q, "q" in wrt, scaled=True), P, wrt if wrt == "p" else "v" + wrt, H0
        )

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


def metric(
    inverse: Sequence[Sequence[str]],
    coords: Sequence[str] = ("t", "x", "y", "z"),
    momenta: Sequence[str] | None = None,
    parameters: Mapping[str, float] | None = None,
    definitions: Mapping[str, str] | Sequence[tuple[str, str]] = (),
    time_scale: str | None = None,
) -> MetricHamiltonian:
    """Photon Hamiltonian H = 1/2 g^ij p_i p_j of any inverse metric (seed Eq. 10)."""
    return MetricHamiltonian(inverse, coords, momenta, parameters, definitions, time_scale)
