"""The paper's directed split (sec. 2) as a sampler with the BSDF interface.

An emitter or a scattering surface with an ``aim`` draws, with probability w (the share), a direction
toward its target aperture (the eye pupil where it is in direct view, an optical system's entrance
pupil or its image, the LCD) and otherwise from its own law. The weight of either kind of sample is
f |cos| / (w p_target + (1 - w) p_own): the one-sample mixture estimator (Veach & Guibas 1995,
doi:10.1145/218380.218498), unbiased for every w in [0, 1). The paper's weights 1/(1 - w) and
I_p Omega_p / (w I_s) are this estimator for a target cone excluded from the surface's own sampling.
Mode "away" draws directions as if they came from the target: a virtual image behind the surface.

:class:`Aimed` wraps a material (or :class:`CosineEmission` for emitters) and offers the same
``sample`` / ``eval`` / ``pdf`` as any material, so the chi-square adapter of the tests checks it
like every other sampler.
"""

from __future__ import annotations

import numpy as np

from ..core.sampling import cosine_hemisphere, frame_from_normal, to_world
from ..core.vec import F32, dot, put, take
from .bsdf import DELTA, REFLECTION, BSDFSample, Interaction

#: When at least this share of the rays is aimed, :meth:`Aimed.sample` evaluates the own law at every
#: ray and keeps the aimed ones, instead of taking those out (the same values either way).
EVAL_EVERY_RAY = 0.5


class CosineEmission:
    """Lambertian emission as a sampler: directions about ``it.ng`` (the emitting side's normal) with
    density cos / pi; f |cos| = cos / pi, so an unaimed sample has weight 1. Directions, weights and
    densities in the precision of ``it.ng``."""

    dims = 2
    flags = REFLECTION

    def sample(self, it: Interaction, u: np.ndarray, mode=None) -> BSDFSample:
        t, b, n = frame_from_normal(it.ng)
        wo = to_world(cosine_hemisphere(u), t, b, n)
        pdf = np.maximum(dot(wo, it.ng), 0) * (1 / np.pi)
        ok = pdf > 0
        return BSDFSample(wo, ok.astype(wo.dtype)[None], pdf, np.where(ok, REFLECTION, 0).astype(np.int8))

    def eval(self, it: Interaction, wo: np.ndarray, mode=None) -> np.ndarray:
        return np.broadcast_to(self.pdf(it, wo), (3, len(it)))

    def pdf(self, it: Interaction, wo: np.ndarray) -> np.ndarray:
        return np.maximum(dot(wo, it.ng), 0) * (1 / np.pi)

    def eval_pdf(self, it: Interaction, wo: np.ndarray, mode=None):
        pdf = self.pdf(it, wo)
        return np.broadcast_to(pdf, (3, len(it))), pdf


class Aimed:
    """A material (or :class:`CosineEmission`) mixed with sampling toward targets.

    Parameters
    ----------
    own : the sampler of the surface's own law.
    aims : {object slot: (target, share, mode)} with target an aperture of tracer.transport.apertures (a
        DiskTarget or MeshTarget), share in [0, 1), mode "toward" or "away". Objects without an entry
        sample their own law only.
    slots : number of object slots in the world.
    """

    def __init__(self, own, aims: dict, slots: int):
        self.own = own
        self.flags = own.flags
        self.share = np.zeros(slots, F32)
        self.which = np.full(slots, -1, np.int64)
        self.sign = np.ones(slots, F32)
        self.targets = []
        for slot, (target, share, mode) in aims.items():
            if target not in self.targets:
                self.targets.append(target)
            self.share[slot] = share
            self.which[slot] = self.targets.index(target)
            self.sign[slot] = -1.0 if mode == "away" else 1.0
        self.dims = 1 + own.dims + max((t.dims for t in self.targets), default=0)

    def _target_pdf(self, it: Interaction, wo: np.ndarray, which: np.ndarray, sign: np.ndarray) -> np.ndarray:
        p = np.zeros(len(it))
        for k, target in enumerate(self.targets):
            sel = np.flatnonzero(which == k)
            if len(sel):
                p[sel] = target.pdf(take(it.p, sel), take(wo, sel) * sign[sel])
        return p

    def sample(self, it: Interaction, u: np.ndarray, mode) -> BSDFSample:
        """u[0] chooses between the target (below the share) and the own law; u[1:1 + own.dims] drives the
        own sample, the rest the target's. Each strategy runs only for the rays that chose it; the
        other's density at the chosen direction makes the mixture pdf."""
        n = len(it)
        share, which, sign = self.share[it.slot], self.which[it.slot], self.sign[it.slot]
        aimed = u[0] < share
        own_idx, aim_idx = np.flatnonzero(~aimed), np.flatnonzero(aimed)
        wo = np.empty((3, n), F32)
        f = np.zeros((3, n), F32)
        p_own = np.zeros(n, F32)
        p_t = np.zeros(n, F32)
        own_flags = np.zeros(n, np.int8)
        if hasattr(self.own, "prepare"):
            self.own.prepare(it)  # frames once, for both subsets
        if len(own_idx):
            sub = it if len(own_idx) == n else it.take(own_idx)
            s = self.own.sample(sub, u[1:1 + self.own.dims, own_idx], mode)
            put(wo, own_idx, s.wo)
            p_own[own_idx] = s.pdf
            own_flags[own_idx] = s.flags
            put(f, own_idx, self.own.eval(sub, s.wo, mode))
        ut = u[1 + self.own.dims:]
        for k, target in enumerate(self.targets):
            sel = aim_idx[which[aim_idx] == k]
            if len(sel):
                d_t, pt = target.sample(take(it.p, sel), take(ut[:target.dims], sel))
                put(wo, sel, d_t * sign[sel])
                p_t[sel] = pt
            back = own_idx[which[own_idx] == k]
            if len(back):  # the target strategy's density at the own samples' directions
                p_t[back] = target.pdf(take(it.p, back), take(wo, back) * sign[back])
        if len(aim_idx) >= EVAL_EVERY_RAY * n:  # the own law's value and density at the aimed directions:
            # at every ray, the aimed ones kept (when most are aimed, cheaper than taking them out and back)
            f_all, p_all = self.own.eval_pdf(it, wo, mode)
            f = np.where(aimed, f_all, f)
            p_own = np.where(aimed, p_all, p_own)
        elif len(aim_idx):
            f_aim, p_own[aim_idx] = self.own.eval_pdf(it.take(aim_idx), take(wo, aim_idx), mode)
            put(f, aim_idx, f_aim)
        mix = share * p_t + (1.0 - share) * p_own
        valid = np.where(aimed, p_t > 0, own_flags != 0) & (mix > 0)
        weight = np.where(valid, f / np.where(valid, mix, 1), 0)
        # An aimed sample's lobe: the own law's non-delta lobes (which side it leaves to is not needed).
        flags = np.where(valid, np.where(aimed, np.int8(self.own.flags & ~DELTA), own_flags), np.int8(0))
        return BSDFSample(wo, weight, np.where(valid, mix, 0), flags.astype(np.int8))

    def eval(self, it: Interaction, wo: np.ndarray, mode) -> np.ndarray:
        return self.own.eval(it, wo, mode)

    def pdf(self, it: Interaction, wo: np.ndarray) -> np.ndarray:
        share, which, sign = self.share[it.slot], self.which[it.slot], self.sign[it.slot]
        return share * self._target_pdf(it, wo, which, sign) + (1.0 - share) * self.own.pdf(it, wo)
