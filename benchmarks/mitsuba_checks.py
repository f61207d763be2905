"""Checks of the Mitsuba mapping (benchmarks/mitsuba_scene.py) that need no reference render.

    DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1 .venv/bin/python benchmarks/mitsuba_checks.py

- sensor: the eye sensor against Mitsuba's own ``thinlens`` on analytic-disk (square pixels, finite
  focus), path and particle tracer, same seed: the images must agree to float rounding;
- diffuser: the Python BSDF's pdf against tracer.core.sampling.gaussian_lobe_pdf (times tau for its value),
  and Mitsuba's chi-square test of its sampling against its pdf (a 20 x 10 degree lobe at 30 degrees
  incidence, so that the test's grid resolves it); the same chi-square test for the Lambertian
  transmitter;
- hdri: a bright spot in a synthetic panorama (rotated 30 degrees) must land on the same pixel in the
  tracer's backward render and in Mitsuba's path render.

Each check prints one Markdown line; mitsuba_peer.py puts them into benchmarks/results/summary.md.
"""

from __future__ import annotations

import math
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402
from mitsuba.chi2 import ChiSquareTest, SphericalDomain  # noqa: E402

from benchmarks import mitsuba_scene as ms  # noqa: E402
from benchmarks.convergence import scene_folder  # noqa: E402
from tracer.core.imageio import write_exr  # noqa: E402
from tracer.core.sampling import frame_from_normal, gaussian_lobe_pdf, to_local  # noqa: E402
from tracer.core.units import luminance  # noqa: E402
from tracer.methods import INTEGRATORS, Budget  # noqa: E402
from tracer.scene import load_scene  # noqa: E402
from tracer.sources.environment import direction_to_equirect  # noqa: E402

#: Largest relative difference (of the image's mean luminance) allowed between the eye sensor and thinlens.
SENSOR_TOLERANCE = 1e-4
#: Largest centroid distance, pixels, between the two renderers' images of the HDRI spot.
SPOT_TOLERANCE_PX = 0.5


def check_sensor() -> tuple[bool, str]:
    """ThinLensEye against Mitsuba's thinlens (same frame, fov, lens, focus, film, seed) on analytic-disk."""
    scene = load_scene(scene_folder("analytic-disk"))
    ours = ms.scene_dict(scene)
    e = scene.eye
    theirs = dict(ours)
    theirs["eye"] = {"type": "thinlens", "fov": e.fov_deg[0], "fov_axis": "x", "aperture_radius": ours["eye"][
        "aperture_radius"], "focus_distance": e.accommodation_distance_mm, "near_clip": 1e-3, "far_clip": 1e7,
        "to_world": ours["eye"]["to_world"], "film": ours["eye"]["film"], "sampler": ours["eye"]["sampler"]}
    worst = 0.0
    for kind in ("path", "ptracer"):
        integrator = ms.integrator(scene, kind)
        a, b = (luminance(np.array(mi.render(mi.load_dict(d), integrator=integrator, spp=256, seed=7)))
                for d in (ours, theirs))
        worst = max(worst, float(np.abs(a - b).max() / max(b.mean(), 1e-300)))
    ok = worst <= SENSOR_TOLERANCE
    return ok, (f"- sensor: the eye sensor against Mitsuba's thinlens on analytic-disk (square pixels), path and "
                f"ptracer, same seed: largest pixel difference {worst:.2g} of the mean "
                f"({'pass' if ok else 'FAIL'}, tolerance {SENSOR_TOLERANCE:g})")


def _surface(wi_local: np.ndarray, n: int):
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.n = mi.Normal3f(0.0, 0.0, 1.0)
    si.sh_frame = mi.Frame3f(si.n)
    si.wi = mi.Vector3f(wi_local)
    return si


def _chi2(plugin: mi.BSDF, wi_local: np.ndarray) -> bool:
    ctx = mi.BSDFContext()

    def sample(s):
        bs, weight = plugin.sample(ctx, _surface(wi_local, dr.width(s)), s[0], mi.Point2f(s[1], s[2]))
        return bs.wo, dr.select(dr.all(weight == 0), 0.0, 1.0)

    def pdf(wo):
        return plugin.pdf(ctx, _surface(wi_local, dr.width(wo)), wo)

    test = ChiSquareTest(domain=SphericalDomain(), sample_func=sample, pdf_func=pdf, sample_dim=3,
                         sample_count=1_000_000)
    return bool(test.run())


def check_bsdfs() -> tuple[bool, str]:
    """The diffuser's pdf against the tracer's, its value = tau pdf, and chi-square tests of both Python BSDFs."""
    sigma = np.sin(np.radians([20.0, 10.0]))
    tau = np.array([0.9, 0.8, 0.7])
    axis = np.array([math.cos(0.3), math.sin(0.3), 0.0])
    diffuser = mi.load_dict({"type": "hud_diffuser", "tau": mi.ScalarColor3f(tau), "sigma_x": float(sigma[0]),
                             "sigma_y": float(sigma[1]), "axis": mi.ScalarVector3f(axis)})
    wi = np.array([math.sin(math.radians(30)), 0.0, math.cos(math.radians(30))])
    rng = np.random.default_rng(3)
    out = rng.normal(size=(4096, 3))
    out /= np.linalg.norm(out, axis=1, keepdims=True)
    si = _surface(wi, len(out))
    wo = mi.Vector3f(out.T)
    pdf = np.array(diffuser.pdf(mi.BSDFContext(), si, wo))
    value = np.array(diffuser.eval(mi.BSDFContext(), si, wo)).T
    # The tracer's frame (GaussianDiffuser._frame): the exit normal -z (the light travels along -wi).
    t, b, n = frame_from_normal(np.tile([[0.0], [0.0], [-1.0]], (1, len(out))), axis)
    beta_d = to_local(np.tile(-wi[:, None], (1, len(out))), t, b, n)[:2]
    expected = gaussian_lobe_pdf(to_local(out.T, t, b, n), beta_d, sigma)
    pdf_err = float(np.abs(pdf - expected).max() / expected.max())
    value_err = float(np.abs(value - tau * expected[:, None]).max() / expected.max())
    transmitter = mi.load_dict({"type": "hud_lambertian_transmitter", "rho": mi.ScalarColor3f(0.2, 0.3, 0.1),
                                "tau": mi.ScalarColor3f(0.5, 0.4, 0.6)})
    chi_diffuser = _chi2(diffuser, wi)
    chi_transmitter = _chi2(transmitter, wi)
    ok = pdf_err < 1e-4 and value_err < 1e-4 and chi_diffuser and chi_transmitter
    return ok, (f"- BSDFs: diffuser pdf against tracer.core.sampling.gaussian_lobe_pdf, largest difference "
                f"{pdf_err:.2g} "
                f"of its peak (value = tau pdf: {value_err:.2g}); chi-square test of sampling against pdf: "
                f"diffuser {'pass' if chi_diffuser else 'FAIL'}, lambertian_transmitter "
                f"{'pass' if chi_transmitter else 'FAIL'}")


def check_hdri() -> tuple[bool, str]:
    """A one-pixel spot in a 256 x 128 panorama rotated by 30 degrees, seen by both renderers."""
    height, width = 128, 256
    spot = np.array([[math.cos(math.radians(20)) * math.cos(math.radians(60)),
                      math.cos(math.radians(20)) * math.sin(math.radians(60)), math.sin(math.radians(20))]])
    u, v = direction_to_equirect(spot.T)
    row, col = int((1 - v[0]) * height), int(u[0] * width)
    image = np.full((height, width), 1e-3)
    image[row, col] = 1.0
    rotation = 30.0
    az = math.radians(60 + rotation + 2.0)  # look a little beside the spot, so that a mirrored image would show
    el = math.radians(18)
    gaze = [math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)]
    with tempfile.TemporaryDirectory() as tmp:
        write_exr(Path(tmp) / "spot.exr", {c: image.astype(np.float32) for c in "RGB"})
        (Path(tmp) / "scene.json").write_text(
            '{"format": "hud-scene", "version": 1, "objects": [], '
            f'"environment": {{"type": "hdri", "file": "spot.exr", "calibration": {{"mode": "scale", "value": 100}}, '
            f'"rotation_deg": {rotation}}}, '
            f'"eye": {{"position": [0, 0, 0], "gaze": {gaze}, "up": [0, 0, 1], "pupil_diameter_mm": 4, '
            '"accommodation_distance_mm": "infinity", "resolution": [60, 40], "fov_deg": [30, 20]}}')
        scene = load_scene(tmp)
        ours = luminance(INTEGRATORS["backward"](scene, 1).render(Budget(rays=2_000_000)).film.rgb())
        theirs = luminance(np.array(mi.render(ms.load(scene), integrator=ms.integrator(scene, "path"), spp=256,
                                              seed=1)))

    def centroid(y):
        w = np.clip(y - np.median(y), 0.0, None)
        j, i = np.indices(y.shape)
        return np.array([(w * i).sum(), (w * j).sum()]) / w.sum()

    c_ours, c_theirs = centroid(ours), centroid(theirs)
    dist = float(np.linalg.norm(c_ours - c_theirs))
    ok = dist <= SPOT_TOLERANCE_PX
    return ok, (f"- HDRI: a spot at azimuth 60 deg, elevation 20 deg of a 256 x 128 panorama rotated by "
                f"{rotation:g} deg lands at pixel ({c_ours[0]:.2f}, {c_ours[1]:.2f}) in the tracer and "
                f"({c_theirs[0]:.2f}, {c_theirs[1]:.2f}) in Mitsuba: {dist:.2f} px apart "
                f"({'pass' if ok else 'FAIL'}, tolerance {SPOT_TOLERANCE_PX:g} px; 1 px = 0.5 deg)")


def run_checks() -> list[str]:
    """All checks; their Markdown lines (none in the scalar variant: they evaluate arrays of samples)."""
    if ms.VARIANT != "llvm_ad_rgb":
        line = f"- checks skipped: they need the llvm variant, this run has {ms.VARIANT}"
        print(line, flush=True)
        return [line]
    lines = []
    for check in (check_sensor, check_bsdfs, check_hdri):
        ok, line = check()
        print(line, flush=True)
        lines.append(line)
    return lines


if __name__ == "__main__":
    run_checks()
