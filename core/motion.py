"""A moving observer: aberration and Doppler shift of what the camera sees (docs/design.md,
"Observer").

Every observer at the camera is a Lorentz boost of the static one (Kerr: the zero-angular-
momentum observer, core/observer.py) by a 3-velocity v (units of c) measured in that
observer's orthonormal frame, whose spatial axes are the local Cartesian (world) axes. A
pixel of the moving camera looks along n' (unit, world axes); the static observer sees the
same photon along

    n = g (n' + (γ² (n'·v) / (γ + 1) − γ) v),   g = 1 / (γ (1 − n'·v)),

which is n_∥ = (cos θ' − β) / (1 − β cos θ'), n_⊥ = g n'_⊥ (the aberration formula,
inverted), and g = ν_moving / ν_static is the Doppler factor of that photon. The rays are
traced from the static observer's directions, so everything else (the tracer, the disk's
redshift, the error estimate) is the static observer's, times g where frequencies enter.

The map n' -> n is conformal on the sphere with local scale g: a final-direction error ε
(radians, static frame) is ε / g radians of the moving camera's view.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .backend import placed
from .blackbody import shifted_colour
from .observer import ObserverError, killing_block, observer_frame

OBSERVERS = ("static", "orbit", "infall")
"""The observers named by a word (core.render's ``observer``); a 3-velocity is the other kind."""
SPEED_LIMIT = 1.0 - 1e-9
"""The largest speed (units of c) an observer may have: γ up to ~2e4."""
EQUATOR = 1e-6
"""|z| / r below which a camera counts as in the equatorial plane ("orbit")."""
_GRADIENT_STEP = 1e-6
"""Relative step of the central differences of r (the infall direction, ~1e-12 accurate)."""


class NoOrbitError(ObserverError):
    """``observer="orbit"``: no circular geodesic orbit passes through the camera."""


@dataclass(frozen=True)
class Motion:
    """The camera's velocity (3,) (world axes, units of c) relative to the static / ZAMO
    observer where it stands, and whether colours take its Doppler shift."""

    velocity: np.ndarray
    shift_colours: bool = True

    @property
    def gamma(self) -> float:
        """The Lorentz factor 1 / √(1 − v²)."""
        return 1.0 / math.sqrt(1.0 - float(self.velocity @ self.velocity))

    def aberrate(self, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(the static observer's look directions (N, 3), g (N,)) of the moving camera's
        unit look directions (N, 3) (the module's formula)."""
        v, gamma = placed(self.velocity, directions), self.gamma
        along = directions @ v
        g = self.doppler(directions)
        coefficient = gamma * gamma * along / (gamma + 1.0) - gamma
        static = g[:, None] * (directions + coefficient[:, None] * v)
        return static / np.linalg.norm(static, axis=1, keepdims=True), g

    def doppler(self, directions: np.ndarray) -> np.ndarray:
        """g = 1 / (γ (1 − n'·v)) (N,): the moving camera's frequency over the static
        observer's for light seen along the unit look directions n' (N, 3)."""
        return 1.0 / (self.gamma * (1.0 - directions @ placed(self.velocity, directions)))

    def colour_shift(self, directions: np.ndarray) -> np.ndarray:
        """The g (N,) colours take along the look directions (N, 3): doppler's, or 1 with
        ``shift_colours`` off."""
        if not self.shift_colours:
            return np.ones_like(directions[:, 0])
        return self.doppler(directions)

    def smallest_doppler(self, camera: Any, chunk: int = 1 << 18) -> float:
        """The smallest g over the camera's pixel centres (the sampler's tolerances in
        radians of the static frame are the pixel's times this: never looser than asked)."""
        smallest = math.inf
        for start in range(0, camera.n_pixels, chunk):
            _, directions = camera.rays(start, min(start + chunk, camera.n_pixels))
            smallest = min(smallest, float(self.doppler(directions).min()))
        return smallest


def shift(rgb: np.ndarray, g: np.ndarray) -> np.ndarray:
    """Linear RGB (N, 3) of static emitters seen with Doppler factors g (N,): each colour as
    a black body of its colour temperature shifted to g T, intensity × g³
    (blackbody.shifted_colour); unchanged where g == 1."""
    out = np.array(rgb, dtype=np.float64)
    moved = np.flatnonzero(g != 1.0)
    if moved.size:
        out[moved] = shifted_colour(out[moved], g[moved], power=3)
    return out


def plain(vector: Any) -> str:
    """A vector as its reader wants it: "(0.8, 0.8, 0)", never numpy's reprs."""
    return "(" + ", ".join(f"{float(v):.6g}" for v in np.ravel(vector)) + ")"


def check_observer(observer: Any) -> str | np.ndarray:
    """``observer`` checked: one of OBSERVERS, or a 3-velocity (3,) of speed below
    SPEED_LIMIT; ValueError naming the problem."""
    if isinstance(observer, str):
        if observer not in OBSERVERS:
            raise ValueError(
                f"observer must be one of {OBSERVERS} or a 3-velocity, got {observer!r}"
            )
        return observer
    if not isinstance(observer, (Sequence, np.ndarray)) or np.shape(observer) != (3,):
        raise ValueError(
            f"observer must be one of {OBSERVERS} or a 3-velocity (vx, vy, vz) in units of c, "
            f"got {_shown(observer)}"
        )
    velocity = np.asarray(observer, dtype=np.float64)
    speed = float(np.linalg.norm(velocity))
    if not np.all(np.isfinite(velocity)) or not speed < SPEED_LIMIT:
        raise ValueError(
            f"observer velocity {plain(velocity)} has speed {speed:.6g} c: it must be below "
            f"the speed of light (at most {SPEED_LIMIT} c)"
        )
    return velocity


def _shown(observer: Any) -> str:
    """``observer`` in a message: numbers plainly (not numpy's reprs), anything else as
    its repr."""
    try:
        return plain(np.asarray(observer, dtype=np.float64))
    except (TypeError, ValueError):
        return repr(observer)


def observer_motion(observer: Any, tracer: Any, position: Any, shift_colours: bool = True):
    """The Motion of ``observer`` (checked: check_observer) at world ``position`` in the
    tracer's scene, or None for the static observer (no velocity)."""
    observer = check_observer(observer)
    if isinstance(observer, str):
        if observer == "static":
            return None
        velocity = _orbit_or_infall(observer, tracer, np.asarray(position, dtype=np.float64))
    else:
        velocity = observer
    if not np.any(velocity):
        return None
    return Motion(velocity, bool(shift_colours))


def _orbit_or_infall(observer: str, tracer: Any, position: np.ndarray) -> np.ndarray:
    """World 3-velocity of the prograde circular geodesic ("orbit") or of the fall from rest
    at infinity (E = 1, L = 0, Carter Q = 0: "infall") through ``position``."""
    model = tracer.model if tracer.curved else None
    orbits = model.kerr_orbits() if model is not None else None
    if orbits is None:
        raise ObserverError(
            f'observer "{observer}" needs a black hole whose orbits are known (Schwarzschild or '
            f"Kerr); this scene's model is {type(model).__name__ if model else 'flat space'}: "
            "give a 3-velocity instead"
        )
    assert model is not None
    X = ((position - tracer.scene.center) @ tracer.rotation).reshape(3, 1)
    mass, a = orbits
    r = float(model.radius_at(X)[0])
    block = killing_block(model, tracer.chart, tracer.chart.to_coords(X))
    g_tt, g_tphi, g_phiphi = (float(x[0]) for x in block)
    omega = -g_tphi / g_phiphi
    lapse = math.sqrt(g_tphi * g_tphi / g_phiphi - g_tt)
    if observer == "orbit":
        speed, unit = _orbit_speed(X, r, mass, a, omega, lapse, g_phiphi), _azimuthal(tracer, X)
    else:
        speed, unit = math.sqrt(max(1.0 - lapse * lapse, 0.0)), -_radial(tracer, X)
    return speed * unit @ tracer.rotation.T


def _orbit_speed(X, r, mass, a, omega, lapse, g_phiphi) -> float:
    """The ZAMO-measured speed (Ω − ω) √g_φφ / α of the prograde circular geodesic at BL
    radius r; NoOrbitError off the equator or where it would reach c (inside the photon
    orbit)."""
    from .geometry.disk import keplerian_omega

    if abs(float(X[2, 0])) > EQUATOR * r:
        raise NoOrbitError(
            f'observer "orbit": the camera is {float(X[2, 0]):.4g} off the hole\'s equatorial '
            "plane; circular orbits lie in it: move the camera to z = 0 in the hole's frame"
        )
    big_omega = float(keplerian_omega(r, mass, a))
    speed = (big_omega - omega) * math.sqrt(g_phiphi) / lapse
    if not 0.0 < speed < SPEED_LIMIT:
        raise NoOrbitError(
            f'observer "orbit": no circular orbit at r = {r:.4g} (a circular orbit there would '
            "move at or above the speed of light: the camera is inside the photon orbit); move "
            "it further out"
        )
    return speed


def _azimuthal(tracer: Any, X: np.ndarray) -> np.ndarray:
    """The unit vector along ξ_φ (the hole's rotation) in the observer's frame at local X
    (3, 1), as local Cartesian components (3,)."""
    if not tracer.spacetime:  # an optical medium: its frame is the local Euclidean one
        return np.array([-X[1, 0], X[0, 0], 0.0]) / math.hypot(X[0, 0], X[1, 0])
    S = tracer.chart.to_coords(X)
    xi_phi = np.zeros(4)
    xi_phi[1:] = tracer.chart.axial_killing(S)[:, 0]
    return _in_frame(tracer, S, xi_phi)


def _radial(tracer: Any, X: np.ndarray) -> np.ndarray:
    """The unit vector along ∇r (r the model's radius) in the observer's frame at local X
    (3, 1), as local Cartesian components (3,): the direction of a fall with L = Q = 0."""
    if not tracer.spacetime:
        return X[:, 0] / np.linalg.norm(X[:, 0])
    chart, model = tracer.chart, tracer.model
    S = chart.to_coords(X)
    step = _GRADIENT_STEP * np.maximum(np.abs(S[:, 0]), np.linalg.norm(X))
    shifts = np.diag(step)  # (3, 3): one column per coordinate
    up = model.radius_at(chart.to_cartesian(S + shifts))
    down = model.radius_at(chart.to_cartesian(S - shifts))
    gradient = np.zeros(4)
    gradient[1:] = (up - down) / (2.0 * step)
    g, _, _ = observer_frame(model, chart, S)
    return _in_frame(tracer, S, np.linalg.solve(g, gradient))


def _in_frame(tracer: Any, S: np.ndarray, vector: np.ndarray) -> np.ndarray:
    """The unit spatial part (3,) of a 4-vector at chart coords S (3, 1) in the observer's
    frame (components along its triad, the local Cartesian axes)."""
    g, u, E = observer_frame(tracer.model, tracer.chart, S)
    components = E.T @ g @ vector
    return components / np.linalg.norm(components)
