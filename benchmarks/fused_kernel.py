"""What a fused kernel would buy: two stages of the path loop written as numba kernels, against the
tracer's own numpy code on the very rays a render gives each stage.

    .venv/bin/python benchmarks/fused_kernel.py [--batches B] [--repeats R]

The first stage: glass (tracer.optics.materials.Dielectric, unpolarised) sampling its branch and the next
ray's origin, i.e. ``Dielectric.sample`` and ``Accelerator.spawn``: Fresnel's R from the incidence
cosine, the branch chosen by R, the reflected or refracted direction (with the shading-normal
fallbacks), the weight, the flags, and the origin offset to the side the ray leaves to. The inputs are
recorded from B batches of a backward render of hud-direct (unpolarised: ``"polarisation": "off"``),
every call of the windshield's material, so the sizes and the mix of front and back faces are a
render's. Both are checked to agree (directions and weights to float32 rounding, the same branch and
flags everywhere but where u lies within float32 rounding of R), then timed (best of R) per ray.

The second stage: the scatterer's Gaussian lobe density (tracer.core.sampling.gaussian_lobe_pdf, an exp per
ray), on the calls the same batches make of it (next-event connections and the mixture's densities),
checked to agree to float32 rounding (numba's exp is the C library's, numpy's its own SIMD one).

This is a measurement for a decision (docs/results/speed.md: the one-process goal needs fused kernels), not
part of the tracer: numba is in requirements-bench.lock only.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import tracer.optics.materials as materials  # noqa: E402
from presets import PRESETS  # noqa: E402
from tracer.core.sampling import gaussian_lobe_pdf  # noqa: E402
from tracer.methods import INTEGRATORS  # noqa: E402
from tracer.optics.bsdf import DELTA, RADIANCE, REFLECTION, TRANSMISSION, Interaction  # noqa: E402
from tracer.optics.materials import Dielectric  # noqa: E402
from tracer.scene import load_scene  # noqa: E402
from tracer.transport.world import World  # noqa: E402

try:
    import numba
except ImportError:  # pragma: no cover - the bench lock installs it
    sys.exit("benchmarks/fused_kernel.py needs numba: .venv/bin/python -m pip install -r requirements-bench.lock")


@numba.njit(cache=True, fastmath=False)
def dielectric_sample(d, p, ng, ns, n_in, n_out, offset, u, radiance, wo, o, weight, flags):
    """One pass over the rays: what Dielectric.sample and Accelerator.spawn compute, ray by ray, in
    float32 for directions (as the tracer) and float64 for positions."""
    one = np.float32(1.0)
    for i in range(d.shape[1]):
        dx, dy, dz = d[0, i], d[1, i], d[2, i]
        gx, gy, gz = ng[0, i], ng[1, i], ng[2, i]
        side = one if dx * gx + dy * gy + dz * gz < 0 else -one
        nx, ny, nz = ns[0, i] * side, ns[1, i] * side, ns[2, i] * side
        front = side > 0
        n_i = n_out[i] if front else n_in[i]
        n_t = n_in[i] if front else n_out[i]
        cos_i = -(dx * nx + dy * ny + dz * nz)
        cos_i = min(max(cos_i, np.float32(0.0)), one)
        eta = n_t / n_i
        sin2_t = (one - cos_i * cos_i) / (eta * eta)
        tir = sin2_t >= one
        cos_t = np.float32(np.sqrt(min(max(one - sin2_t, np.float32(0.0)), one)))
        den_s, den_p = cos_i + eta * cos_t, eta * cos_i + cos_t
        rs = (cos_i - eta * cos_t) / (den_s if den_s > 0 else one)
        rp = (eta * cos_i - cos_t) / (den_p if den_p > 0 else one)
        r = one if tir else np.float32(0.5) * (rs * rs + rp * rp)
        if tir:
            cos_t = np.float32(0.0)
        refl = u[i] < r
        if refl:
            k = np.float32(2.0) * (dx * nx + dy * ny + dz * nz)
            wx, wy, wz = dx - k * nx, dy - k * ny, dz - k * nz
            if (wx * gx + wy * gy + wz * gz > 0) != (side > 0):  # about the geometric normal instead
                k = np.float32(2.0) * (dx * gx + dy * gy + dz * gz)
                wx, wy, wz = dx - k * gx, dy - k * gy, dz - k * gz
            weight[i] = one
            flags[i] = DELTA | REFLECTION
        else:
            inv = one / eta
            c = cos_i * inv - cos_t
            wx, wy, wz = dx * inv + c * nx, dy * inv + c * ny, dz * inv + c * nz
            s = one / np.float32(np.sqrt(wx * wx + wy * wy + wz * wz))
            wx, wy, wz = wx * s, wy * s, wz * s
            if (wx * gx + wy * gy + wz * gz > 0) != (side < 0):  # the straight continuation instead
                wx, wy, wz = dx, dy, dz
            weight[i] = one / (eta * eta) if radiance else one
            flags[i] = DELTA | TRANSMISSION
        wo[0, i], wo[1, i], wo[2, i] = wx, wy, wz
        off = offset[i] if wx * gx + wy * gy + wz * gz >= 0 else -offset[i]
        o[0, i], o[1, i], o[2, i] = p[0, i] + off * gx, p[1, i] + off * gy, p[2, i] + off * gz


@numba.njit(cache=True, fastmath=False)
def lobe_pdf(d, beta0, sigma, out):
    """gaussian_lobe_pdf ray by ray: g2(beta - beta0; sigma) d_z for d_z > 0, else 0 (float32)."""
    for i in range(d.shape[1]):
        s0, s1 = sigma[0, i], sigma[1, i]
        zx = (d[0, i] - beta0[0, i]) * (np.float32(1.0) / s0)
        zy = (d[1, i] - beta0[1, i]) * (np.float32(1.0) / s1)
        g2 = np.exp(np.float32(-0.5) * (zx * zx + zy * zy)) * (np.float32(1.0) / (np.float32(2 * np.pi) * s0 * s1))
        out[i] = g2 * d[2, i] if d[2, i] > 0 else np.float32(0.0)


def record(batches: int):
    """The glass's calls and the lobe density's in ``batches`` backward batches of hud-direct:
    (world, [(material, it, u, mode)], [(d, beta0, sigma)])."""
    with tempfile.TemporaryDirectory() as tmp:
        folder = PRESETS["hud-direct"].write(Path(tmp) / "s")
        data = json.loads((folder / "scene.json").read_text())
        (folder / "scene.json").write_text(json.dumps(data | {"polarisation": "off"}))
        world = World(load_scene(folder))
    calls, lobes = [], []
    original, original_pdf = Dielectric.sample, materials.gaussian_lobe_pdf

    def rec(self, it, u, mode):
        calls.append((self, Interaction(it.d, it.p, it.ng, it.ns, it.uv, it.slot, it.offset), u.copy(), mode))
        return original(self, it, u, mode)

    def rec_pdf(d, beta0, sigma):
        lobes.append((d.copy(), beta0.copy(), np.array(sigma, d.dtype)))  # sigma as the tracer gives it
        return original_pdf(d, beta0, sigma)

    Dielectric.sample, materials.gaussian_lobe_pdf = rec, rec_pdf
    try:
        integ = INTEGRATORS["backward"](world, 1)
        for k in range(batches):
            integ.trace_batch(k)
    finally:
        Dielectric.sample, materials.gaussian_lobe_pdf = original, original_pdf
    return world, calls, lobes


def numpy_stage(world, mat, it, u, mode):
    it = Interaction(it.d, it.p, it.ng, it.ns, it.uv, it.slot, it.offset)  # nothing cached
    s = mat.sample(it, u, mode)
    return s, world.accel.spawn(it.p, it.ng, s.wo, it.offset)


def fused_stage(mat, it, u, mode):
    n = len(it)
    n_in = np.ascontiguousarray(np.broadcast_to(mat.gather(mat.n_in, it), (n,)), np.float32)
    n_out = np.ascontiguousarray(np.broadcast_to(mat.gather(mat.n_out, it), (n,)), np.float32)
    wo, o = np.empty((3, n), np.float32), np.empty((3, n))
    weight, flags = np.empty(n, np.float32), np.empty(n, np.int8)
    dielectric_sample(it.d, it.p, it.ng, it.ns, n_in, n_out, it.offset, np.ascontiguousarray(u[0]),
                      mode == RADIANCE, wo, o, weight, flags)
    return wo, o, weight, flags


def best_time(fn, items, repeats: int) -> float:
    """Seconds of ``fn`` over every item, best of ``repeats``."""
    best = np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        for c in items:
            fn(c)
        best = min(best, time.perf_counter() - t)
    return best


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--batches", type=int, default=4)
    ap.add_argument("--repeats", type=int, default=7)
    args = ap.parse_args()
    world, calls, lobes = record(args.batches)
    rays = sum(len(c[1]) for c in calls)
    print(f"glass: recorded {len(calls)} calls ({rays:,} rays, {rays / max(len(calls), 1):,.0f} per call) "
          f"from {args.batches} backward batches of hud-direct")
    # Agreement, call by call.
    worst_dir = worst_o = 0.0
    disagree = 0
    for mat, it, u, mode in calls:
        s, o_np = numpy_stage(world, mat, it, u, mode)
        wo, o, weight, flags = fused_stage(mat, it, u, mode)
        same = flags == s.flags
        disagree += int((~same).sum())
        worst_dir = max(worst_dir, float(np.abs(wo[:, same] - s.wo[:, same]).max(initial=0)))
        worst_o = max(worst_o, float(np.abs(o[:, same] - o_np[:, same]).max(initial=0)))
        w_np = np.broadcast_to(s.weight[0], (len(it),))
        np.testing.assert_allclose(weight[same], w_np[same], rtol=1e-6)
    print(f"glass: branch differs at {disagree} of {rays:,} rays (u within rounding of R); largest difference "
          f"elsewhere: directions {worst_dir:.2e}, origins {worst_o:.2e} mm")
    assert disagree <= 1e-4 * rays and worst_dir < 1e-5 and worst_o < 1e-6
    # Speed: each stage over every recorded call, best of the repeats.
    t_np = best_time(lambda c: numpy_stage(world, c[0], c[1], c[2], c[3]), calls, args.repeats)
    t_nb = best_time(lambda c: fused_stage(c[0], c[1], c[2], c[3]), calls, args.repeats)
    print(f"glass: numpy (the tracer) {1e9 * t_np / rays:.1f} ns per ray, numba {1e9 * t_nb / rays:.1f}: "
          f"numba {t_np / t_nb:.1f} x as fast")

    n_lobe = sum(c[0].shape[1] for c in lobes)
    # The kernel's inputs: contiguous planes, sigma per ray, and an output array, made before timing.
    kernel_args = [tuple(np.ascontiguousarray(a, np.float32) for a in
                         (d, beta0, np.broadcast_to(sigma.reshape(2, -1), (2, d.shape[1]))))
                   + (np.empty(d.shape[1], np.float32),) for d, beta0, sigma in lobes]
    worst = 0.0
    for (d, beta0, sigma), args_nb in zip(lobes, kernel_args, strict=True):
        lobe_pdf(*args_nb)
        out, ref = args_nb[3], gaussian_lobe_pdf(d, beta0, sigma)
        worst = max(worst, float((np.abs(out - ref) / np.maximum(ref.max(initial=0), 1e-30)).max(initial=0)))
    print(f"lobe density: {len(lobes)} calls, {n_lobe:,} rays; largest difference {worst:.1e} of the call's peak")
    assert worst < 1e-5
    t_np = best_time(lambda c: gaussian_lobe_pdf(*c), lobes, args.repeats)
    t_nb = best_time(lambda c: lobe_pdf(*c), kernel_args, args.repeats)
    print(f"lobe density: numpy (the tracer) {1e9 * t_np / n_lobe:.1f} ns per ray, numba {1e9 * t_nb / n_lobe:.1f}: "
          f"numba {t_np / t_nb:.2f} x as fast")


if __name__ == "__main__":
    main()
