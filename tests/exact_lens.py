"""The exact Schwarzschild lens for a static observer, by quadrature (an independent
reference for the ray differentials and the point stars): the angle a light ray sweeps,
the sky angle each image angle sees, the magnification of an image, and where a star's
images lie."""

import math

from scipy.integrate import quad
from scipy.optimize import brentq


def swept_to_infinity(b: float, mass: float, r_from: float | None = None) -> float:
    """The angle φ a Schwarzschild light ray of impact parameter b sweeps from r_from (or
    from its periapsis) out to infinity: ∫ du / √(1/b² − u² + 2 M u³), u = 1/r."""

    def f(u):
        return 1.0 / b**2 - u * u + 2.0 * mass * u**3

    if r_from is not None:
        return quad(lambda u: 1.0 / math.sqrt(f(u)), 0.0, 1.0 / r_from, epsabs=1e-14,
                    epsrel=1e-13, limit=200)[0]  # fmt: skip
    top = brentq(f, 0.0, 1.0 / (3.0 * mass), xtol=1e-16)  # the periapsis' u
    slope = top * (2.0 - 6.0 * mass * top)  # -f'(top) top: f(top (1 - s²)) ~ slope s²

    def smooth(s):  # u = top (1 - s²): the 1/√ end point is gone
        if s == 0.0:
            return 2.0 * top / math.sqrt(slope * top)
        return 2.0 * s * top / math.sqrt(f(top * (1.0 - s * s)))

    return quad(smooth, 0.0, 1.0, epsabs=1e-14, epsrel=1e-13, limit=200)[0]


def swept_angle(alpha: float, mass: float, r_obs: float) -> float:
    """Δφ swept from a static observer at r_obs to infinity by the ray leaving at angle
    alpha from the hole's direction: impact parameter b = r sin α / √(1 − 2M/r)."""
    b = r_obs * math.sin(alpha) / math.sqrt(1.0 - 2.0 * mass / r_obs)
    if alpha > math.pi / 2:  # moving out from the start
        return swept_to_infinity(b, mass, r_obs)
    return 2.0 * swept_to_infinity(b, mass) - swept_to_infinity(b, mass, r_obs)


def exact_magnification(alpha: float, mass: float, r_obs: float) -> float:
    """|μ| of the image a static observer at r_obs sees at angle alpha from the hole:
    sin α = (b / r) √(1 − 2M/r) (the static frame), the sky angle Θ = π − Δφ(b) from the
    axis behind the hole, μ = sin α / |sin Θ dΘ/dα| (dΔφ/dα by central differences of
    the quadrature)."""
    h = 1e-5
    rate = (swept_angle(alpha + h, mass, r_obs) - swept_angle(alpha - h, mass, r_obs)) / (2 * h)
    return math.sin(alpha) / abs(math.sin(swept_angle(alpha, mass, r_obs)) * rate)


def shadow_angle(mass: float, r_obs: float) -> float:
    """The shadow's angular radius for a static observer: sin α = (3√3 M / r) √(1 − 2M/r)."""
    return math.asin(3 * math.sqrt(3) * mass / r_obs * math.sqrt(1 - 2 * mass / r_obs))


def image_angles(theta: float, mass: float, r_obs: float) -> tuple[float, float]:
    """The angles from the hole (primary, secondary) of the two images of a star at sky angle
    theta (0 < theta < π) from the axis behind the hole: π − Δφ(α) = theta on the star's
    side, −theta on the other (the secondary, inside the Einstein ring)."""
    low = shadow_angle(mass, r_obs) * (1 + 1e-6)
    high = math.pi / 2 - 1e-9

    def side(sign):
        return brentq(lambda a: math.pi - swept_angle(a, mass, r_obs) - sign * theta, low, high,
                      xtol=1e-14)  # fmt: skip

    return side(1.0), side(-1.0)
