"""Brightness-theorem analysis: a deterministic second method for what the eye should see.

For a grid of retina pixels the chief ray (through the pupil centre) is followed through every
specular branch (mirror, LCD, coating, both Fresnel branches of a dielectric) with the product of the
reflectances and transmittances along it. A branch ends on an emitter (its luminance), in the
environment, or on a scattering surface, whose outgoing luminance toward the eye is integrated
deterministically from the emitters it sees directly (quadrature over each emitter triangle, with
shadow rays). The predicted apparent luminance of the branch is the product times that luminance:
the brightness theorem (luminance is conserved along a lossless specular chain; see
../shared/reference/hud-physics.md, "Photometry").

Each distinct chain (the sequence of objects and events) is one *path*; in a HUD the dominant path
is the symbol image (windshield reflection, mirror, LCD, the scatterer behind it) and the chain
that refracts into the windshield and reflects at its outer surface is the ghost image.
"""

from __future__ import annotations

import math

import numpy as np

from .optics.surfaces import Emitter, Interaction
from .units import luminance
from .vec import dot, norm

#: Branches whose factor falls below this (relative to the chief ray) are dropped.
MIN_FACTOR = 1e-5


def _emitter_quadrature(integrator, level: int = 4):
    """Quadrature points of all emitter triangles: points (q, 3), normals (q, 3), weights (q,) mm^2,
    luminance RGB (q, 3), two-sided flags (q,)."""
    pts, nrm, wts, lum, two = [], [], [], [], []
    # Midpoints of a level x level subdivision of the barycentric triangle (equal-area cells).
    cells = []
    for i in range(level):
        for j in range(level - i):
            cells.append(((i + 1 / 3) / level, (j + 1 / 3) / level))
            if i + j < level - 1:
                cells.append(((i + 2 / 3) / level, (j + 2 / 3) / level))
    b = np.array(cells)
    for slot, surf in enumerate(integrator.surfaces):
        if not isinstance(surf, Emitter):
            continue
        t = integrator.objects[slot].triangles
        cross = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        area = 0.5 * np.linalg.norm(cross, axis=1)
        e1, e2 = t[:, None, 1] - t[:, None, 0], t[:, None, 2] - t[:, None, 0]
        p = t[:, None, 0] + b[None, :, :1] * e1 + b[None, :, 1:] * e2
        pts.append(p.reshape(-1, 3))
        nrm.append(np.repeat(cross / (2 * area)[:, None], len(b), axis=0))
        wts.append(np.repeat(area / len(b), len(b)))
        lum.append(np.tile(surf.radiance_rgb, (len(t) * len(b), 1)))
        two.append(np.full(len(t) * len(b), surf.two_sided))
    if not pts:
        return None
    return tuple(np.concatenate(a) for a in (pts, nrm, wts, lum, two))


def _scattered_luminance(integrator, surf, it: Interaction, quad, chunk: int = 1 << 20) -> np.ndarray:
    """(m, 3) luminance (cd/m^2) leaving scattering points toward the eye (against it.d), from the
    emitters in direct view: the sum over quadrature points of f L_e cos_i cos_e / d^2 dA, with one
    shadow-ray batch (one Embree call) per chunk of point pairs."""
    m = len(it)
    out = np.zeros((m, 3))
    if quad is None or m == 0:
        return out
    qp, qn, qw, ql, q2 = quad
    to_eye = -it.d
    cos_o = np.maximum(np.abs(dot(to_eye, it.ng)), 1e-12)
    step = max(1, chunk // m)
    for k0 in range(0, len(qp), step):
        k = np.arange(k0, min(k0 + step, len(qp)))
        # Pairs (surface point i, quadrature point k), flattened i-major: (m * len(k), 3).
        v = (qp[k][None, :, :] - it.p[:, None, :]).reshape(-1, 3)
        dist = norm(v)
        w_in = -v / dist[:, None]  # light travels from the emitter point to the surface
        kk = np.tile(k, m)
        ii = np.repeat(np.arange(m), len(k))
        cos_e = dot(w_in, qn[kk])
        ng, ns = it.ng[ii], it.ns[ii]
        origin = integrator.accel.spawn(it.p[ii], ng, -w_in)
        blocked = integrator.accel.intersect(origin, -w_in, tmax=dist * (1 - 1e-5) - 1e-2).hit
        light = Interaction(w_in, it.p[ii], ng, ns, None if it.uv is None else it.uv[ii])
        f = surf.eval_fcos(light, to_eye[ii]) / cos_o[ii][:, None]
        g = np.where(((cos_e > 0) | q2[kk]) & ~blocked, np.abs(dot(w_in, ng)) * np.abs(cos_e) * qw[kk] / dist**2, 0.0)
        contrib = f * ql[kk] * g[:, None]
        out += contrib.reshape(m, len(k), 3).sum(axis=1)
    return out


def specular_paths(integrator, stride: int | None = None, max_depth: int = 12, directions: np.ndarray | None = None):
    """Follow chief rays of a pixel grid (or along given world ``directions`` (p, 3) from the pupil
    centre) through all specular branches.

    Returns a dict with ``pixels`` (p,) flat indices analysed (or 0..p-1 for given directions),
    ``stride``, ``grid`` and ``paths``: a list of {"path": str, "pixel" (k,) positions into
    ``pixels``, "luminance" (k, 3) predicted cd/m^2, "factor" (k,) Y of the product of R and T,
    "lcd" (k,) the first LCD's transmittance relative to a clear cell, NaN if none}.
    """
    eye = integrator.eye
    w, h = eye.width, eye.height
    if directions is not None:
        stride, jj = 1, np.zeros((1, len(directions)))
        pixels = np.arange(len(directions))
        dirs = directions / np.linalg.norm(directions, axis=1, keepdims=True)
        origins = np.repeat(eye.position[None], len(dirs), axis=0)
    else:
        if stride is None:
            stride = max(1, math.ceil(math.sqrt(w * h / 40000)))
        jj, ii = np.meshgrid(np.arange(stride // 2, h, stride), np.arange(stride // 2, w, stride), indexing="ij")
        pixels = (jj * w + ii).ravel()
        sx, sy = eye.pixel_centers()
        origins, dirs, _ = eye.generate_rays(sx[pixels % w], sy[pixels // w], np.zeros((len(pixels), 2)))
    quad = _emitter_quadrature(integrator)
    env = integrator.scene.environment
    n = len(pixels)
    factor = np.ones((n, 3))
    owner = np.arange(n)
    lcd = np.full(n, np.nan)
    sig = np.zeros(n, np.int64)
    names = {0: ()}
    codes: dict[tuple, int] = {(): 0}
    leaves: dict[int, list] = {}

    def code(parent: int, label: str) -> int:
        key = names[parent] + (label,)
        if key not in codes:
            codes[key] = len(codes)
            names[codes[key]] = key
        return codes[key]

    def leaf(s_idx, lum, f, own, lc):
        for s in np.unique(s_idx):
            k = s_idx == s
            leaves.setdefault(int(s), []).append((own[k], lum[k], f[k], lc[k]))

    accel = integrator.accel
    for _ in range(max_depth):
        if len(owner) == 0 or accel is None:
            break
        hits = accel.intersect(origins, dirs)
        miss = ~hits.hit
        if np.any(miss) and not env.is_black:
            s_miss = np.array([code(s, "environment") for s in sig[miss]])
            leaf(s_miss, factor[miss] * env.radiance(dirs[miss]), factor[miss], owner[miss], lcd[miss])
        nxt = {k: [] for k in ("o", "d", "f", "own", "lcd", "sig")}
        for slot, sel in hits.by_object():
            surf = integrator.surfaces[slot]
            it = integrator.interaction(slot, hits, sel, dirs)
            name = integrator.objects[slot].name
            if surf.emits:
                s_e = np.array([code(s, name) for s in sig[sel]])
                leaf(s_e, factor[sel] * surf.emitted(it), factor[sel], owner[sel], lcd[sel])
            if surf.terminal:
                continue
            if surf.scattering:
                s_s = np.array([code(s, f"{name}:scatter") for s in sig[sel]])
                leaf(s_s, factor[sel] * _scattered_luminance(integrator, surf, it, quad), factor[sel],
                     owner[sel], lcd[sel])
                continue
            for d_out, f_branch, label in surf.branches(it):
                f_new = factor[sel] * f_branch
                keep = luminance(f_new) > MIN_FACTOR
                if surf.kind == "lcd":
                    rel = luminance(f_branch) / float(luminance(surf.t_open))
                    lc = np.where(np.isnan(lcd[sel]), rel, lcd[sel])
                else:
                    lc = lcd[sel]
                k = np.nonzero(keep)[0]
                nxt["o"].append(accel.spawn(it.p[k], it.ng[k], d_out[k]))
                nxt["d"].append(d_out[k])
                nxt["f"].append(f_new[k])
                nxt["own"].append(owner[sel[k]])
                nxt["lcd"].append(lc[k])
                nxt["sig"].append(np.array([code(s, f"{name}:{label}") for s in sig[sel[k]]], dtype=np.int64))
        if not nxt["o"]:
            break
        origins, dirs, factor = (np.concatenate(nxt[k]) for k in ("o", "d", "f"))
        owner, lcd, sig = (np.concatenate(nxt[k]) for k in ("own", "lcd", "sig"))
    paths = []
    for s, parts in leaves.items():
        own = np.concatenate([p[0] for p in parts])
        lum = np.concatenate([p[1] for p in parts])
        fac = np.concatenate([p[2] for p in parts])
        lc = np.concatenate([p[3] for p in parts])
        paths.append({"path": " > ".join(names[s]), "pixel": own, "luminance": lum, "factor": luminance(fac),
                      "lcd": lc})
    paths.sort(key=lambda p: -float(luminance(p["luminance"]).sum()))
    return {"pixels": pixels, "stride": stride, "grid": jj.shape, "paths": paths}
