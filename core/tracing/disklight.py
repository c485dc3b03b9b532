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
  ray starts its integration at the region's boundary when the camera is outside it).

Charts: Kerr–Schild (Kerr; Schwarzschild as Kerr–Schild with a = 0), Boyer–Lindquist
(Kerr traced in its own chart), and Schwarzschild's isotropic optical medium (explicit
splittings), whose momentum is the spatial part of −k/E: p_t = 1 there. Rays are traced
backwards (p = −k), which flips p_t, p_φ and both p·u alike: g is their ratio.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..geometry import Hits
from ..geometry.disk import AccretionDisk
from ..observer import killing_block, killing_energy, zamo_omega
from .scene import DISK_ID, ENDING
from .segments import RayResults


class DiskLight:
    """The disk's redshift and colour for one tracer's model and chart."""

    def __init__(self, disk: AccretionDisk, model: Any, chart: Any, to_local: Any) -> None:
        self.disk, self.model, self.chart, self.to_local = disk, model, chart, to_local

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
        cam = killing_block(self.model, self.chart, self.chart.to_coords(camera))
        seen = killing_energy(cam, p_t, p_phi, zamo_omega(cam[1], cam[2]))
        with np.errstate(all="ignore"):
            return seen / emitted

    def record(self, rows, hits: Hits, got: np.ndarray, state, out: RayResults) -> None:
        """Colour and redshift of the rays ``rows`` whose recorded hit (``got``) is on the
        disk; ``state`` = (Q, P, camera) of those rays (step end, local camera). A ray whose
        g is not a finite positive number is flagged failed."""
        on = np.flatnonzero(got & (hits.object_id == DISK_ID))
        if on.size == 0:
            return
        Q, P, camera = (a[:, on] for a in state)
        X = self.to_local(hits.position[on]).T
        p_t, p_phi = self.momenta(Q, P)
        g = self.redshift(X, p_t, p_phi, camera)
        bad = ~(np.isfinite(g) & (g > 0))
        g = np.where(bad, np.nan, g)
        r = rows[on]
        out.redshift[r] = g
        out.surface[r, :3] = self.disk.colour(np.where(bad, 0.0, g), self.model.radius_at(X))
        out.surface[r, 3] = 1.0
        out.ending[r[bad]] = ENDING["failed"]
