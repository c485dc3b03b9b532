"""Light of the accretion disk where rays hit it: redshift g and black-body colour.

The disk (core.geometry.disk) is cast like any surface (a flat annulus in the model's
equatorial plane, object id ``DISK_ID``), its hits found on the step's cubic path. Where a
ray ends on it, g = ν_obs / ν_emit = (p·u)_cam / (p·u)_disk from the ray's momentum:

- The gas moves along ξ_t + Ω ξ_φ (circular orbit, Killing vectors of the stationary,
  axisymmetric hole), so p·u_disk = u^t (p_t + Ω p_φ) needs only p_t = p·ξ_t and
  p_φ = p·ξ_φ, which are conserved along the ray: read at the step's end, they are the
  hit's, with no interpolation error. u^t = 1 / √−g(ξ_t + Ω ξ_φ, ξ_t + Ω ξ_φ) comes from
  the tracing chart's own metric at the hit (observer.killing_block).
- The camera is the zero-angular-momentum observer (static where a = 0) at each ray's
  origin, the observer of core/observer.py, evaluated there with the same constants (the
  ray starts its integration at the region's boundary when the camera is outside it). A
  moving camera (core.motion) sees g times its Doppler factor (RayResults.doppler).

An opaque disk ends the ray with its colour; a translucent one (opacity a < 1) adds a x its
light to the ray's radiance and keeps (1 - a) of what lies behind, like a volume, and the ray
goes on (the redshift pass keeps the first crossing's g).

Charts: Kerr–Schild (Kerr; Schwarzschild as Kerr–Schild with a = 0), Boyer–Lindquist
(Kerr traced in its own chart, and kerr_bl: Kerr–Schild Kerr's form for the explicit
split, core/models/kerr_split.py), and Schwarzschild's isotropic optical medium (explicit
splittings), whose momentum is the spatial part of −k/E: p_t = 1 there. Rays are traced
backwards (p = −k), which flips p_t, p_φ and both p·u alike: g is their ratio.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..backend import array_module, to_host
from ..geometry import Hits
from ..geometry.disk import AccretionDisk
from ..observer import killing_block, killing_energy, zamo_omega
from .scene import DISK_ID, ENDING
from .segments import RayResults, SceneGeometry


class DiskLight:
    """The disk's redshift and colour for one tracer's model and chart."""

    def __init__(
        self,
        disk: AccretionDisk,
        model: Any,
        chart: Any,
        to_local: Any,
        geometry: SceneGeometry,
        behind: SceneGeometry,
    ) -> None:
        """``geometry``: the scene's objects with the disk; ``behind``: without it."""
        self.disk, self.model, self.chart, self.to_local = disk, model, chart, to_local
        self.geometry, self.behind = geometry, behind

    def momenta(self, Q: np.ndarray, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The conserved p_t = p·ξ_t and p_φ = p·ξ_φ (each (M,)) of states (Q, P)."""
        off = self.chart.offset
        S = Q[off:]
        p_phi = np.einsum("ij,ij->j", self.chart.axial_killing(S), P[off:])
        p_t = P[0] if self.chart.time_index is not None else np.ones_like(p_phi)
        return p_t, p_phi

    def redshift(self, X_hit: np.ndarray, p_t, p_phi, camera: np.ndarray) -> np.ndarray:
        """g (M,) of rays with constants p_t, p_φ hitting the disk at local X_hit (3, M),
        seen from local camera positions (3, M); NaN where undefined."""
        block = killing_block(self.model, self.chart, self.chart.to_coords(X_hit))
        if self.disk.doppler:
            omega = self.disk.orbit_omega(self.model.radius_at(X_hit))
        else:
            omega = zamo_omega(block[1], block[2])
        emitted = killing_energy(block, p_t, p_phi, omega)
        one = camera.shape[1] > 1 and bool(np.all(camera == camera[:, :1]))  # a pinhole
        cam = killing_block(
            self.model, self.chart, self.chart.to_coords(camera[:, :1] if one else camera)
        )
        seen = killing_energy(cam, p_t, p_phi, zamo_omega(cam[1], cam[2]))
        with np.errstate(all="ignore"):
            return seen / emitted

    def record_hits(self, rows, a, b, hits: Hits, state, out: RayResults) -> np.ndarray:
        """Record the hits of segments a -> b of the rays ``rows`` (``state`` = (Q, P,
        camera) of those rays: step end, local camera), the disk's with its light.
        -> (M,) bool: the rays that ended (an opaque surface, or a failed g)."""
        if self.opaque:
            got = self.geometry.record_hits(rows, a, b, hits, out)
            on = np.flatnonzero(got & (hits.object_id == DISK_ID))
            if on.size:
                self.shade(rows[on], hits.position[on], [x[:, on] for x in state], out)
            return got
        return self._through(rows, a, b, hits, state, out)

    @property
    def opaque(self) -> bool:
        """Whether the disk ends the rays that hit it."""
        return self.disk.opacity >= 1.0

    def shade(self, rows, X_world, state, out: RayResults) -> None:
        """The colour of an opaque disk where the rays ``rows`` ended on it, at world points
        X_world (K, 3) (``state``: (Q, P, camera) of those rays, see record_hits)."""
        rgb, _ = self._light(rows, X_world, state, slice(None), out)
        out.surface[rows, :3] = rgb
        out.surface[rows, 3] = 1.0

    def _through(self, rows, a, b, hits: Hits, state, out: RayResults) -> np.ndarray:
        """A translucent disk: a ray crossing it gains opacity x its light (behind the
        volumes' light before it), keeps (1 - opacity) of what lies behind and goes on to
        the chord's end (cast again without the disk: a surface there ends it)."""
        cross = hits.hit & (hits.object_id == DISK_ID)
        got = np.zeros_like(rows, dtype=bool)
        other = np.flatnonzero(~cross)
        got[other] = self.geometry.record_hits(rows[other], a[other], b[other],
                                               hits.take(other), out)  # fmt: skip
        on = np.flatnonzero(cross)
        if on.size == 0:
            return got
        r, p = rows[on], hits.position[on]
        out.accumulate(r, *self.geometry.volume_light(a[on], p, Hits.miss(on.size, on)))
        rgb, bad = self._light(r, p, state, on, out)
        alpha = self.disk.opacity
        out.radiance[r] += (alpha * out.transmittance[r])[:, None] * rgb
        out.transmittance[r] *= 1.0 - alpha
        got[on] = bad
        go = on[~bad]
        got[go] = self.behind.record(rows[go], hits.position[go], b[go], out)
        return got

    def _light(self, r, X_world, state, on, out: RayResults):
        """(RGB (K, 3), bad (K,)) of the disk at world points X_world hit by the rays ``r``
        (``on``: their columns in ``state``); the first g of each ray goes to
        out.redshift; a ray whose g is not a finite positive number is flagged failed and
        gets no light."""
        Q, P, camera = (x[:, on] for x in state)
        g, rgb = self._seen(X_world, Q, P, camera, out.doppler[r])
        bad = ~(np.isfinite(g) & (g > 0))
        g = np.where(bad, np.nan, g)
        first = np.isnan(out.redshift[r])
        out.redshift[r[first]] = g[first]
        out.ending[r[bad]] = ENDING["failed"]
        return rgb, bad

    def _seen(self, X_world, Q, P, camera, doppler) -> tuple[np.ndarray, np.ndarray]:
        """(g (K,), RGB (K, 3)) of the disk at world points X_world (K, 3) reached in states
        (Q, P) from local cameras (3, K) moving with ``doppler`` (no light where g is not a
        finite positive number). A device's rays have theirs worked out on the host (the
        observer frames and the black-body tables are host code: core.backend)."""
        xp = array_module(Q)
        if xp is not np:
            host = (to_host(x) for x in (X_world, Q, P, camera, doppler))
            return tuple(xp.asarray(x) for x in self._seen(*host))
        X = self.to_local(X_world).T
        p_t, p_phi = self.momenta(Q, P)
        g = self.redshift(X, p_t, p_phi, camera) * doppler  # the camera's motion
        bad = ~(np.isfinite(g) & (g > 0))
        return g, self.disk.colour(np.where(bad, 0.0, g), self.model.radius_at(X))
