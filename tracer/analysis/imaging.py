"""The imaging of one specular chain, ray by ray: chief rays solved onto PGU points, thin bundles over the
pupil, and the angles the eye reads them at. The metrics of :mod:`.optics` are built on these.

- **Angles.** A direction d is read in the vehicle's frame (forward f, right r, up u): azimuth h =
  atan2(d.r, d.f), positive to the right, and elevation v = asin(d.u), positive up.
- **Chief rays.** The direction from an eye point that lands on a given PGU point through the chain is
  found by Newton's method on (h, v), with the Jacobian of the landing point by differences of
  :data:`EPS_ANGLE`, and steps halved where a full one lands worse or off the chain.
- **Thin bundles.** Around a chief ray d0 from eye point E, with e_h (horizontal) and e_v = e_h x d0
  across it, rays start from E + delta (delta in the plane across d0, :data:`EPS_PUPIL` mm) and leave
  along d0 + theta (small angles). Their landing point x(delta, theta) has the Jacobians J_o = dx/d delta
  and J_d = dx/d theta (central differences); the rays of the bundle that meet at the PGU point have
  theta = -V delta with V = J_d^-1 J_o, the bundle's vergence matrix (1/mm): for a stigmatic image at
  distance D, V = I / D. Its diagonal gives the vergences of the horizontal (sagittal) and vertical
  (tangential) sections, and the difference of its eigenvalues the astigmatism (the generalised
  Coddington equations; O. N. Stavroudis, "The Mathematics of Geometrical and Physical Optics", Wiley
  2006, ch. 10; for a spherical mirror met at angle theta, f_t = (R/2) cos theta and f_s = (R/2) / cos
  theta).
- **Spot.** Rays from points spread over the pupil, each solved onto the PGU point, read by an eye
  focused at the bundle's mean vergence: the angular offsets theta + V_mean delta are the spot.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..transport.sequential import Chain, Plane, follow

#: Angle step of the chief-ray solver's Jacobian and of the thin bundles' directions, rad.
EPS_ANGLE = 1e-4
#: Pupil offset of the thin bundles, mm.
EPS_PUPIL = 0.5
#: The solver stops where every landing point is within this distance of its target, mm (0.1 um on the
#: PGU: 1e-7 rad of image angle through a magnification of about 8 at 2.5 m).
TOLERANCE_MM = 1e-4
#: A solve that no step improves is kept within this distance of its target, mm (1 um on the PGU:
#: 0.01 arcmin of image angle at hud-direct's magnification and VID).
STUCK_MM = 10 * TOLERANCE_MM
NEWTON_STEPS = 20
HALVINGS = 8


@dataclass
class VehicleFrame:
    """The vehicle's axes (unit (3,) world vectors): forward, right and up."""

    forward: np.ndarray
    right: np.ndarray
    up: np.ndarray

    def angles(self, d: np.ndarray) -> np.ndarray:
        """(2, n) azimuth h and elevation v (rad) of unit directions ``d`` (3, n)."""
        return np.stack([np.arctan2(self.right @ d, self.forward @ d), np.arcsin(np.clip(self.up @ d, -1, 1))])

    def helmholtz(self, d: np.ndarray) -> np.ndarray:
        """(2, n) Helmholtz angles (rad) of unit directions ``d`` (3, n): the elevation atan2(d.u, d.f), a
        turn about the right (interocular) axis, then the azimuth asin(d.r). Two eyes on a line along
        ``right`` that look at one point share its elevation, so vertical disparity (dipvergence) is read
        in these angles (K. Moffitt, "Comprehensive guidelines for binocular display alignment", 2003)."""
        return np.stack([np.arcsin(np.clip(self.right @ d, -1, 1)), np.arctan2(self.up @ d, self.forward @ d)])

    def direction(self, hv: np.ndarray) -> np.ndarray:
        """(3, n) unit directions of angles ``hv`` (2, n) rad."""
        h, v = hv
        return (np.cos(v) * np.cos(h) * self.forward[:, None] + np.cos(v) * np.sin(h) * self.right[:, None]
                + np.sin(v) * self.up[:, None])

    def gnomonic(self, hv: np.ndarray, centre: np.ndarray) -> np.ndarray:
        """(2, n) coordinates (rad, tangents) of the directions ``hv`` (2, n) on the plane across the
        direction ``centre`` (2,): right and up, as a flat image square to that line of sight shows them."""
        c = self.direction(centre.reshape(2, 1))
        e_h, e_v = self.across(c)
        d = self.direction(hv)
        z = (d * c).sum(axis=0)
        return np.stack([(d * e_h).sum(axis=0), (d * e_v).sum(axis=0)]) / z

    def across(self, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(e_h, e_v), each (3, n): unit vectors across directions ``d`` (3, n), e_h horizontal (to the
        right), e_v = e_h x d (up)."""
        e_h = np.cross(d.T, self.up).T
        e_h /= np.linalg.norm(e_h, axis=0)
        e_v = np.cross(e_h.T, d.T).T
        return e_h, e_v


class Imaging:
    """One chain of a world from eye points to the PGU's ``plane``, seen in ``frame``."""

    def __init__(self, world, chain: Chain, plane: Plane, frame: VehicleFrame):
        self.world, self.chain, self.plane, self.frame = world, chain, plane, frame

    def land(self, eyes: np.ndarray, d: np.ndarray):
        """The landing (tracer.transport.sequential.Landing) of rays from ``eyes`` along ``d`` (3, n)."""
        return follow(self.world, self.chain, self.plane, eyes, d)

    def _land_hv(self, eyes, hv):
        lnd = self.land(eyes, self.frame.direction(hv))
        return lnd.xy, lnd.ok

    def solve(self, eyes: np.ndarray, targets: np.ndarray, guess: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Chief rays: the angles (2, n) rad from eye points ``eyes`` (3, n) whose rays land on the PGU
        points ``targets`` (2, n) mm, from the first ``guess`` (2, n); and (n,) whether each converged
        (NaN angles where not)."""
        hv = guess.astype(np.float64).copy()
        xy, ok = self._land_hv(eyes, hv)
        err = xy - targets
        done = np.zeros(hv.shape[1], bool)
        for _ in range(NEWTON_STEPS):
            dist = np.sqrt((err * err).sum(axis=0))
            done = ok & (dist <= TOLERANCE_MM)
            act = np.flatnonzero(ok & ~done)
            if len(act) == 0:
                break
            e, a = eyes[:, act], hv[:, act]
            jac = np.empty((2, 2, len(act)))
            for k in range(2):
                step = np.zeros_like(a)
                step[k] = EPS_ANGLE
                xk, okk = self._land_hv(e, a + step)
                jac[:, k] = np.where(okk, (xk - xy[:, act]) / EPS_ANGLE, np.nan)
            det = jac[0, 0] * jac[1, 1] - jac[0, 1] * jac[1, 0]
            r = err[:, act]
            delta = -np.stack([jac[1, 1] * r[0] - jac[0, 1] * r[1], -jac[1, 0] * r[0] + jac[0, 0] * r[1]]) / det
            scale = np.ones(len(act))
            pending = np.isfinite(delta).all(axis=0)
            old = dist[act]
            for _ in range(HALVINGS):
                idx = np.flatnonzero(pending)
                if len(idx) == 0:
                    break
                trial = a[:, idx] + scale[idx] * delta[:, idx]
                xt, okt = self._land_hv(e[:, idx], trial)
                dt = np.sqrt(((xt - targets[:, act[idx]]) ** 2).sum(axis=0))
                better = okt & (dt < old[idx])
                g = act[idx[better]]
                hv[:, g], xy[:, g], err[:, g] = trial[:, better], xt[:, better], xt[:, better] - targets[:, g]
                pending[idx[better]] = False
                scale[idx[~better]] *= 0.5
            stuck = act[pending]  # no step helped: as close as this guess gets
            ok[stuck] = ok[stuck] & (dist[stuck] <= STUCK_MM)
            done[stuck] = ok[stuck]
        dist = np.sqrt((err * err).sum(axis=0))
        good = ok & (dist <= STUCK_MM)
        # a chief ray that something else blocks before the PGU: the eye does not see that point
        k = np.flatnonzero(good)
        if len(k):
            good[k[self.land(eyes[:, k], self.frame.direction(hv[:, k])).vignetted[:]]] = False
        hv[:, ~good] = np.nan
        return hv, good

    def vergence(self, eyes: np.ndarray, hv: np.ndarray) -> np.ndarray:
        """(2, 2, n) vergence matrices V (1/mm) of the thin bundles around the chief rays ``hv`` (2, n)
        from ``eyes`` (3, n), in the (e_h, e_v) axes across each ray (NaN where a bundle ray fails)."""
        d0 = self.frame.direction(hv)
        e_h, e_v = self.frame.across(d0)
        n = d0.shape[1]
        j_o = np.empty((2, 2, n))
        j_d = np.empty((2, 2, n))
        for k, e in enumerate((e_h, e_v)):
            plus, minus = self.land(eyes + EPS_PUPIL * e, d0), self.land(eyes - EPS_PUPIL * e, d0)
            j_o[:, k] = (plus.xy - minus.xy) / (2 * EPS_PUPIL)
            dp, dm = d0 + EPS_ANGLE * e, d0 - EPS_ANGLE * e
            plus = self.land(eyes, dp / np.linalg.norm(dp, axis=0))
            minus = self.land(eyes, dm / np.linalg.norm(dm, axis=0))
            j_d[:, k] = (plus.xy - minus.xy) / (2 * EPS_ANGLE)
        return np.einsum("ijn,jkn->ikn", _inverse(j_d), j_o)

    def spot(self, eye: np.ndarray, hv: np.ndarray, targets: np.ndarray, vergence: np.ndarray,
             pupil_radius_mm: float, rings: int = 3) -> np.ndarray:
        """(n,) RMS radius (rad) of the spots of PGU points ``targets`` (2, n) whose chief rays from the
        one eye point ``eye`` (3,) are ``hv`` (2, n), for an eye focused at each bundle's mean vergence
        (``vergence`` (2, 2, n)): rays from ``rings`` rings of pupil points (1 + 6 + 12 + ... of them,
        equal areas), each solved onto its PGU point."""
        pts = [np.zeros(2)]
        for k in range(1, rings + 1):
            m = 6 * k
            a = 2 * np.pi * (np.arange(m) + 0.5 * (k % 2)) / m
            r = pupil_radius_mm * np.sqrt((k - 0.5) / rings) if rings else 0.0
            pts += list(np.stack([r * np.cos(a), r * np.sin(a)], 1))
        pupil = np.array(pts).T  # (2, P)
        n, p = hv.shape[1], pupil.shape[1]
        d0 = self.frame.direction(hv)
        e_h, e_v = self.frame.across(d0)
        ii = np.repeat(np.arange(n), p)
        delta = np.tile(pupil, n)  # (2, n P)
        starts = eye[:, None] + delta[0] * e_h[:, ii] + delta[1] * e_v[:, ii]
        theta0 = -np.einsum("ijn,jn->in", vergence[:, :, ii], delta)
        guess = self.frame.angles(_unit(d0[:, ii] + theta0[0] * e_h[:, ii] + theta0[1] * e_v[:, ii]))
        sol, ok = self.solve(starts, targets[:, ii], guess)
        d = self.frame.direction(sol)
        cos = (d * d0[:, ii]).sum(axis=0)
        theta = np.stack([(d * e_h[:, ii]).sum(axis=0), (d * e_v[:, ii]).sum(axis=0)]) / cos
        mean_v = 0.5 * (vergence[0, 0] + vergence[1, 1])
        blur = theta + mean_v[ii] * delta  # where each ray lands on the retina of an eye focused at 1 / mean_v
        ok = ok.reshape(n, p)
        blur = np.where(ok, blur.reshape(2, n, p), 0.0)
        count = ok.sum(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):  # a point none of whose rays lands: NaN
            centred = blur - blur.sum(axis=2, keepdims=True) / count[:, None]
            return np.sqrt(np.where(ok, (centred ** 2).sum(axis=0), 0.0).sum(axis=1) / count)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=0)


def _inverse(m: np.ndarray) -> np.ndarray:
    """Inverses of (2, 2, n) matrices (NaN where singular)."""
    det = m[0, 0] * m[1, 1] - m[0, 1] * m[1, 0]
    det = np.where(det != 0, det, np.nan)
    return np.stack([np.stack([m[1, 1], -m[0, 1]]), np.stack([-m[1, 0], m[0, 0]])]) / det
