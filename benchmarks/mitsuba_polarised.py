"""Polarisation against an independent renderer: Mitsuba 3's polarised variant, its RGB variant and the
tracer on a windshield and a panel.

    .venv/bin/python benchmarks/mitsuba_polarised.py [--spp N]

The scene is tests/optics/test_polarisation.py's (plate_scene of tests/support/scenes.py): a glass plate
(n = 1.52) met at 67 deg reflects a 1000 cd/m^2 Lambertian panel into the eye. Each renderer gives the
panel's luminance seen through the plate over its luminance seen directly (a ratio, so that Mitsuba's
spectral upsampling of RGB drops out):

1. a 4.76 mm plate, unpolarised panel: the plate's reflectance with all its internal reflections,
   the mean over s and p of R + T^2 R / (1 - R^2) (0.2282); an RGB renderer's unpolarised Fresnel
   average gives 0.2465;
2. the same behind a linear polariser sheet (Mitsuba's ``polarizer``, turned to 0 and 90 deg; the
   tracer: an s- or p-polarised panel), the ratio taken to the panel seen through the same sheet:
   s light 0.4150, p light 0.0413;
3. a 20 mm plate and a 3 mm strip: the ghost image apart from the primary one, the ghost-to-primary
   ratio of the image rows.

Mitsuba renders with ``scalar_spectral_polarized`` and ``scalar_rgb`` (its path tracer, pinhole
camera, 16 x 48 or 4 x 4 pixels); the tracer with the backward method. Prints a Markdown table and
writes benchmarks/results/mitsuba_polarised.md. Needs mitsuba (requirements-bench.lock; make bench).
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import mitsuba as mi  # noqa: E402

from presets._build import frame_matrix  # noqa: E402
from tracer.core.units import Y_WEIGHTS  # noqa: E402
from tracer.methods import INTEGRATORS, Budget  # noqa: E402
from tracer.scene import load_scene  # noqa: E402
from tracer.transport.world import World  # noqa: E402

THETA = math.radians(67.0)
NORMAL = np.array([0.0, -math.cos(THETA), math.sin(THETA)])
HIT = np.array([0.0, 200.0, 0.0])
GAZE = np.array([0.0, 1.0, 0.0])
REFLECTED = GAZE - 2 * (GAZE @ NORMAL) * NORMAL
PANEL = HIT + 150.0 * REFLECTED


def _transform(frame, scale):
    m = np.array(frame) @ np.diag([scale[0], scale[1], scale[2], 1.0])
    return mi.ScalarTransform4f(m)


def mitsuba_scene(thickness: float | None, strip: bool, polariser_deg: float | None, direct: bool, res, fov_deg):
    """The scene in Mitsuba's own shapes: ``direct`` looks at the panel without the plate (the camera at
    the eye's image in the plate, looking along the reflected gaze)."""
    w, h = (20.0, 1.5) if strip else (20.0, 20.0)
    eye = np.zeros(3)
    look = GAZE
    if direct:
        eye = -2 * ((-HIT) @ NORMAL) * NORMAL  # the eye's image: the same panel distance and angle
        look = REFLECTED
    up = np.cross(np.cross(look, [0.0, 0.0, 1.0]), look)
    d = {"type": "scene",
         "sensor": {"type": "perspective", "fov": fov_deg[1], "fov_axis": "y",
                    "to_world": mi.ScalarTransform4f().look_at(origin=eye.tolist(), target=(eye + look).tolist(),
                                                               up=(up / np.linalg.norm(up)).tolist()),
                    "film": {"type": "hdrfilm", "width": res[0], "height": res[1], "rfilter": {"type": "box"},
                             "pixel_format": "rgb"},
                    "sampler": {"type": "independent"}},
         "panel": {"type": "rectangle", "to_world": _transform(frame_matrix(PANEL, [1, 0, 0], -REFLECTED), (w, h, 1)),
                   "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [1000.0] * 3}},
                   "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.0] * 3}}}}
    if thickness is not None and not direct:
        center = HIT - 0.5 * thickness * NORMAL
        d["plate"] = {"type": "cube", "to_world": _transform(frame_matrix(center, [1, 0, 0], NORMAL),
                                                              (150.0, 150.0, 0.5 * thickness)),
                      "bsdf": {"type": "dielectric", "int_ior": 1.52, "ext_ior": 1.0}}
    if polariser_deg is not None:  # a sheet 1 mm in front of the panel
        d["sheet"] = {"type": "rectangle",
                      "to_world": _transform(frame_matrix(PANEL + 1.0 * (-REFLECTED), [1, 0, 0], -REFLECTED),
                                             (w + 5, h + 5, 1)),
                      "bsdf": {"type": "polarizer", "theta": polariser_deg}}
    return d


#: Independent Mitsuba renders (seeds) of each image: their spread gives its standard error.
SEEDS = 8


def mitsuba_y(variant: str, spp: int, **kw) -> list[np.ndarray]:
    """Y images of :data:`SEEDS` renders with different seeds."""
    mi.set_variant(variant)
    scene = mi.load_dict(mitsuba_scene(**kw))
    integrator = mi.load_dict({"type": "path", "max_depth": 16, "rr_depth": 16})
    return [np.array(mi.render(scene, integrator=integrator, spp=spp, seed=k))[..., :3] @ Y_WEIGHTS
            for k in range(SEEDS)]


def mean_se(values) -> tuple[float, float]:
    v = np.asarray(values, dtype=np.float64)
    return float(v.mean()), float(v.std(ddof=1) / math.sqrt(len(v)))


def ratio_se(through: list[np.ndarray], direct: list[np.ndarray]) -> tuple[float, float]:
    """Mean image luminance through the plate over that seen directly, with its standard error."""
    (a, sa), (b, sb) = mean_se([t.mean() for t in through]), mean_se([d.mean() for d in direct])
    r = a / b
    return r, r * math.hypot(sa / a, sb / b)


def ours(folder: Path, rays: int, seed: int = 3) -> tuple[np.ndarray, float]:
    """The backward render's Y image and the standard error of its mean."""
    res = INTEGRATORS["backward"](World(load_scene(folder)), seed).render(Budget(rays=rays))
    y = res.film.rgb() @ Y_WEIGHTS
    return y, math.sqrt(float(res.film.variance_y().sum())) / y.size


def main():
    from tests.support.optics import fresnel_angles, plate_total
    from tests.support.scenes import plate_scene

    ap = argparse.ArgumentParser()
    ap.add_argument("--spp", type=int, default=256)
    args = ap.parse_args()
    rs, rp = fresnel_angles(67.0)
    rows = []
    small = {"res": (4, 4), "fov_deg": (0.1, 0.1), "strip": False}
    pol_v, rgb_v = "scalar_spectral_polarized", "scalar_rgb"
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        # 1. unpolarised panel, 4.76 mm plate.
        closed = 0.5 * (plate_total(rs) + plate_total(rp))
        got = {v: ratio_se(mitsuba_y(v, args.spp, thickness=4.76, polariser_deg=None, direct=False, **small),
                           mitsuba_y(v, args.spp, thickness=None, polariser_deg=None, direct=True, **small))
               for v in (pol_v, rgb_v)}
        y, se = ours(plate_scene(tmp / "u"), 400_000)
        rows.append(("4.76 mm plate, unpolarised panel: reflectance", closed, (y.mean() / 1000, se / 1000), got[pol_v],
                     got[rgb_v]))
        # 2. through a polariser sheet turned to 0 and 90 deg: the brighter is s light.
        pol = {deg: ratio_se(mitsuba_y(pol_v, args.spp, thickness=4.76, polariser_deg=deg, direct=False, **small),
                             mitsuba_y(pol_v, args.spp, thickness=None, polariser_deg=deg, direct=True, **small))
               for deg in (0.0, 90.0)}
        m_s, m_p = sorted(pol.values(), key=lambda v: -v[0])
        for light, closed_v, m in (("s", plate_total(rs), m_s), ("p", plate_total(rp), m_p)):
            axis = 0.0 if light == "s" else 90.0
            y, se = ours(plate_scene(tmp / light, emitter={"polarisation": {"axis_deg": axis}}), 400_000)
            rows.append((f"4.76 mm plate, {light} light: reflectance", closed_v, (y.mean() / 1000, se / 1000), m, None))
        # 3. the ghost apart: 20 mm plate, a strip, the images on different rows.
        tall = {"res": (16, 48), "fov_deg": (1.6, 6.0), "strip": True}
        ratios = {v: mean_se([_ghost_ratio(img.sum(axis=1)) for img in
                              mitsuba_y(v, args.spp // 4, thickness=20.0, polariser_deg=None, direct=False, **tall)])
                  for v in (pol_v, rgb_v)}
        # The tracer: the spread of four seeds, as Mitsuba's.
        ghosts = [_ghost_ratio(ours(plate_scene(tmp / f"g{k}", 20.0, strip=True, resolution=(4, 48),
                                                fov=(0.4, 6.0)), 200_000, seed=3 + k)[0].sum(axis=1))
                  for k in range(4)]
        rows.append(("20 mm plate, strip: ghost / primary (image rows)", None, mean_se(ghosts), ratios[pol_v],
                     ratios[rgb_v]))
    lines = [f"| quantity | closed form | tracer (backward) | Mitsuba {pol_v} | Mitsuba {rgb_v} |",
             "|---|---|---|---|---|"]

    def fmt(v):
        if v is None:
            return ""
        if isinstance(v, tuple):
            return f"{v[0]:.4f}" + (f" ± {v[1]:.2g}" if v[1] is not None else "")
        return f"{v:.4f}"

    lines += [f"| {q} | {fmt(c)} | {fmt(t)} | {fmt(p)} | {fmt(r)} |" for q, c, t, p, r in rows]
    text = "\n".join(lines)
    print(text)
    out = ROOT / "benchmarks" / "results" / "mitsuba_polarised.md"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(f"Made by `benchmarks/mitsuba_polarised.py --spp {args.spp}` (± standard errors; Mitsuba: the "
                   f"spread of {SEEDS} seeds).\n\n{text}\n")


def _ghost_ratio(profile: np.ndarray) -> float:
    """Ghost over primary from a row profile with two separate images: the split is the emptiest row
    between the two brightest groups."""
    lit = profile > 1e-3 * profile.max()
    rows = np.flatnonzero(lit)
    gaps = np.flatnonzero(np.diff(rows) > 1)
    if len(gaps) == 0:
        raise RuntimeError("the two images are not apart")
    split = rows[gaps[0]] + 1
    a, b = profile[:split].sum(), profile[split:].sum()
    primary, ghost = (a, b) if a > b else (b, a)
    return float(ghost / primary)


if __name__ == "__main__":
    main()
