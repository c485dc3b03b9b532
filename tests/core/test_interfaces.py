"""The written interfaces: what a method and a model provide, no probing."""

import numpy as np
import pytest

import core
from core import hamiltonians as hm
from core.integrators import METHODS, Method, integrate
from core.integrators.system import DuckSystem, System, as_system
from core.trace import ERROR_CONSTANTS


@pytest.mark.parametrize("name", sorted(METHODS))
def test_every_method_states_its_properties(name):
    m = METHODS[name]
    assert isinstance(m, Method) and m.name == name and m.order >= 1
    assert isinstance(m.symplectic, bool) and isinstance(m.explicit, bool)
    assert m.error_constant is None or m.error_constant > 0
    assert ERROR_CONSTANTS.get(name) == m.error_constant
    # options keep the constant (the step rule reads it after with_options(tol=...))
    if m.accepts("tol"):
        assert m.with_options(tol=1e-10).error_constant == m.error_constant


def test_explicit_methods():
    explicit = {n for n, m in METHODS.items() if m.explicit}
    splittings = {"leapfrog", "blanes_moan4", "blanes_moan6", "blanes_moan_s6", "blanes_moan_s10"}
    assert explicit == {"rk4", "dopri5", "tao2", "tao4"} | splittings
    assert core.get_method("yoshida4", base="tao2").explicit


def test_error_constants_are_read_only():
    with pytest.raises(TypeError):
        ERROR_CONSTANTS["gauss4"] = 1.0  # type: ignore[index]


def test_models_are_systems_with_the_tracer_interface():
    models = [
        hm.schwarzschild(),
        hm.kerr(1.0, 0.4),
        hm.kerr(1.0, 0.4, chart="kerr_schild"),
        hm.minkowski(),
        hm.minkowski("spherical"),
        hm.medium("1 + 0.1*x"),
        hm.from_expression("0.5*p**2 + q**2", q=["q"], p=["p"]),
    ]
    for m in models:
        assert isinstance(m, hm.Hamiltonian) and isinstance(m, System)
        # a split where the model offers one (media), None elsewhere
        assert (m.split_parts() is None) == (m.kind != "medium")
        assert isinstance(m.for_backward_tracing(), hm.Hamiltonian)
    # Schwarzschild's form for the explicit splittings is its isotropic optical medium
    optical = hm.schwarzschild().for_backward_tracing(explicit_split=True)
    assert optical.chart.name == "isotropic" and optical.split_parts() is not None
    assert type(hm.minkowski()) is hm.Minkowski and hm.minkowski().flat
    assert not hm.schwarzschild().flat
    ks = hm.kerr(1.0, 0.4, chart="kerr_schild")
    assert ks.horizon == hm.kerr_horizon(1.0, 0.4) and ks.mass == 0.5 and ks.scales_time
    assert ks.capture_test() is not None and hm.medium("1").capture_test() is None
    # Schwarzschild is followed in outgoing Kerr–Schild coordinates with a = 0
    back = hm.schwarzschild(2.0).for_backward_tracing()
    assert isinstance(back, hm.KerrSchild) and back.outgoing and back.a == 0.0
    X = np.array([[3.0, 0.0], [0.0, 1.0], [4.0, 0.5]])
    np.testing.assert_allclose(hm.schwarzschild().radius_at(X), np.linalg.norm(X, axis=0))
    np.testing.assert_allclose(ks.radius_at(X), ks.radius_soa(np.vstack([np.zeros(2), X])))


class _Oscillator:
    """A duck-typed H (the required members only)."""

    dim, separable = 1, True

    def value_soa(self, Q, P):
        return 0.5 * (P[0] ** 2 + Q[0] ** 2)

    def gradient_soa(self, Q, P, wrt="qp"):
        return (Q.copy() if "q" in wrt else None), (P.copy() if "p" in wrt else None)

    def value_gradient_soa(self, Q, P):
        return self.value_soa(Q, P), Q.copy(), P.copy()


def test_duck_typed_hamiltonians_get_the_optional_defaults():
    H = as_system(_Oscillator())
    assert isinstance(H, DuckSystem) and as_system(H) is H
    Q = np.array([[1.0, 2.0]])
    g, dg = H.time_scale_soa(Q)
    assert g.tolist() == [1.0, 1.0] and not dg.any()
    assert H.frozen_q(Q) is None and H.capture_test() is None and H.subset([0]) is H
    res = integrate(_Oscillator(), [1.0], [0.0], step=0.01, steps=100, method="gauss4")
    assert abs(res.q[0] - np.cos(1.0)) < 1e-8


def test_get_method_refuses_non_methods():
    with pytest.raises(TypeError, match="not an integration method"):
        core.get_method(object())


def test_only_kerrs_own_metric_is_traced_in_kerrs_other_forms():
    """A metric in (t, r, theta, phi) with a = 0 and rg > 0 that is not Schwarzschild's (here
    Reissner–Nordström's, Q = 0.3) is traced as written, and no disk orbits it; Schwarzschild
    and Kerr themselves go to their other forms and carry their orbits (M, a)."""
    from core.models.spacetimes import SphericalSpacetime

    f = "(1 - rg/r + 0.09/r**2)"
    inverse = [[f"-1/{f}", "0", "0", "0"], ["0", f, "0", "0"], ["0", "0", "1/r**2", "0"],
               ["0", "0", "0", "1/(r**2*sin(theta)**2)"]]  # fmt: skip
    charged = SphericalSpacetime(inverse, 1.0, 0.0, time_scale="r - rg", horizon=0.9)
    assert charged.for_backward_tracing() is charged
    assert charged.for_backward_tracing(explicit_split=True) is charged
    assert charged.kerr_orbits() is None
    with pytest.raises(ValueError, match="accretion disk needs a black hole"):
        core.Scene(model=charged, disk=core.AccretionDisk(r_out=10.0))
    schwarzschild = hm.schwarzschild(1.0)
    assert type(schwarzschild.for_backward_tracing()).__name__ == "KerrSchild"
    assert type(schwarzschild.for_backward_tracing(True)).__name__ == "SchwarzschildOptical"
    for model in (schwarzschild, hm.kerr(1.0, 0.3), hm.kerr(1.0, 0.3, chart="kerr_schild")):
        assert model.kerr_orbits() == (0.5, model.a)
        assert model.for_backward_tracing(True).kerr_orbits() == (0.5, model.a)
