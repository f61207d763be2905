"""The optical analysis's figures for docs/results/optics.md, measured:

    .venv/bin/python benchmarks/optics.py [--images docs/images]

- its time on hud-direct (the design eye point, the 9 x 5 eye points and binocular pairs, the whole
  analysis with the mesh comparison), best of three;
- hud-direct's summary, and what the mirror's 160 x 110 cell mesh costs each metric against its exact
  ellipsoid (the analysis's mesh_comparison);
- the closed forms of ../shared/reference/hud-optical-metrics.md against the analysis (tests/support/imaging.py's
  scenes, the numbers tests/analysis/test_optics.py holds to 1 % or 0.01 mrad);
- hud-direct-wedge's wedge: the zero of the ghost's vertical offset over a sweep of the wedge, against
  the reference's first-order formula;
- hud-direct-curved's figures against hud-direct's;
- with --images: the three pictures of `hud-trace optics hud-direct` and the rendered ghost of
  hud-direct beside hud-direct-wedge's (a grid of one-pixel lines seen through 0.25 arcmin pixels).
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from presets import PRESETS, hud_direct  # noqa: E402
from presets.hud_direct_optics import WEDGE_MRAD, first_order_wedge_mrad  # noqa: E402
from tests.support import imaging  # noqa: E402
from tests.support.render import render  # noqa: E402
from tracer.analysis.optics import Analysis, analyse  # noqa: E402
from tracer.core.imageio import write_png  # noqa: E402
from tracer.products import charts  # noqa: E402
from tracer.products.optics import distortion_chart, eyebox_chart, vid_chart  # noqa: E402
from tracer.scene import load_scene  # noqa: E402
from tracer.transport.world import World  # noqa: E402

MRAD_PER_ARCMIN = math.pi / (180 * 60) * 1e3


def timing(folder: Path) -> dict:
    scene = load_scene(folder)
    best = {"design_eye": math.inf, "eyebox": math.inf, "analysis": math.inf, "with_mesh_comparison": math.inf}
    for _ in range(3):
        t0 = time.perf_counter()
        out = Analysis(World(scene)).run()
        best["analysis"] = min(best["analysis"], time.perf_counter() - t0)
        best["design_eye"] = min(best["design_eye"], out["seconds"]["design_eye"])
        best["eyebox"] = min(best["eyebox"], out["seconds"]["eyebox"])
        t0 = time.perf_counter()
        analyse(scene)
        best["with_mesh_comparison"] = min(best["with_mesh_comparison"], time.perf_counter() - t0)
    return best


def closed_forms(tmp: Path) -> list[tuple[str, float, float, str]]:
    rows = []

    def run(folder, **kw):
        return Analysis(World(load_scene(folder))).run(**kw)

    s = run(imaging.plane_mirror(tmp / "pm"))
    rows.append(("plane mirror VID", s["summary"]["design_eye"]["vid_mm"], 1000.0, "mm"))
    pair = next(p for p in s["pairs"] if p["midpoint_mm"] == [0.0, 0.0])
    rows.append(("vergence angle, 1 m", pair["vergence_angle_mrad"][7], 2e3 * math.atan(32.5 / 1000), "mrad"))
    rows.append(("plane mirror dipvergence", s["summary"]["eyebox"]["dipvergence_mrad"], 0.0, "mrad"))
    d = run(imaging.sphere_on_axis(tmp / "so"), eyebox=False)["summary"]["design_eye"]
    si = 350 * 500 / (500 - 350)
    rows.append(("sphere on axis VID", d["vid_mm"], 400 + si, "mm"))
    rows.append(("sphere on axis magnification", d["magnification_h"], si / 350, "1"))
    d = run(imaging.sphere_off_axis(tmp / "oa"), eyebox=False)["summary"]["design_eye"]
    th = math.radians(15)
    ft, fs = 500 * math.cos(th), 500 / math.cos(th)
    vt, vs = 600 + 300 * ft / (ft - 300), 600 + 300 * fs / (fs - 300)
    rows += [("Coddington tangential VID", d["vid_tangential_mm"], vt, "mm"),
             ("Coddington sagittal VID", d["vid_sagittal_mm"], vs, "mm"),
             ("astigmatism", d["astigmatism_centre_d"], abs(1 / vt - 1 / vs) * 1e3, "D")]
    flat = run(imaging.plate(tmp / "pl"), eyebox=False)["summary"]["design_eye"]
    rows.append(("flat plate ghost d / VID", flat["ghost_separation_centre_arcmin"] * MRAD_PER_ARCMIN,
                 imaging.plate_offset(4.76, 1.52, 65) / 2500 * 1e3, "mrad"))
    wedge = run(imaging.plate(tmp / "pw", wedge_mrad=0.2), eyebox=False)["summary"]["design_eye"]
    moved = (flat["ghost_offset_v_arcmin"] - wedge["ghost_offset_v_arcmin"]) * MRAD_PER_ARCMIN
    rows.append(("wedge 0.2 mrad, seen from the eye", moved, imaging.wedge_deviation(0.2, 1.52, 65) * 1e3 * 1700 / 2500,
                 "mrad"))
    return rows


def wedge_zero(tmp: Path) -> tuple[float, list]:
    """The wedge (mrad) where hud-direct-wedge's ghost offset at the design eye point crosses 0 (secant
    steps from 0 and the preset's), and the (wedge, offset arcmin) pairs met."""
    def offset(w):
        folder = hud_direct.write(tmp / f"w{w:.6f}", windshield={"wedge_mrad": w})
        return Analysis(World(load_scene(folder))).run(eyebox=False, spot=False)["summary"]["design_eye"][
            "ghost_offset_v_arcmin"]

    pts = [(0.0, offset(0.0)), (WEDGE_MRAD, offset(WEDGE_MRAD))]
    for _ in range(4):
        (a, fa), (b, fb) = pts[-2], pts[-1]
        if abs(fb) < 1e-6 or fb == fa:
            break
        c = b - fb * (b - a) / (fb - fa)
        pts.append((c, offset(c)))
    return pts[-1][0], pts


def ghost_picture(tmp: Path, path: Path):
    """hud-direct's and hud-direct-wedge's grid line at the image's centre, 0.25 arcmin pixels, side by side."""
    images = []
    for name, kw in (("flat", {}), ("wedge", {"windshield": {"wedge_mrad": WEDGE_MRAD}})):
        f = imaging.hud_direct_grid(tmp / f"g-{name}", {"fov_deg": [1.0, 0.5], "resolution": [240, 120]}, **kw)
        y, _, _ = render(f, "backward", 3_000_000, seed=1)
        images.append(y)
    top = max(float(im.max()) for im in images)
    fig, canvas = charts.new_figure(9.0, 2.9)
    for k, (im, title) in enumerate(zip(images, ("hud-direct: flat windshield, ghost 3.9 arcmin above",
                                                 f"hud-direct-wedge: {WEDGE_MRAD:g} mrad wedge, one line"),
                                        strict=True)):
        ax = fig.add_axes((0.06 + 0.44 * k, 0.14, 0.4, 0.7))
        shown = ax.imshow(im, cmap=charts.colour_map(), vmin=0, vmax=top, extent=(-30, 30, -15, 15))
        ax.set_title(title, loc="left")
        ax.set_xlabel(charts.label("azimuth from the image centre", "arcmin"))
        if k == 0:
            ax.set_ylabel(charts.label("elevation", "arcmin"))
    bar = fig.colorbar(shown, cax=fig.add_axes((0.9, 0.14, 0.012, 0.7)))
    bar.set_label("luminance, cd/m²")
    write_png(path, charts.pixels(canvas))
    return images


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--images", type=Path, default=None, help="write the pictures into this folder")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as t:
        tmp = Path(t)
        folder = PRESETS["hud-direct"].write(tmp / "hud-direct")
        best = timing(folder)
        print("hud-direct, seconds (best of 3): " + ", ".join(f"{k} {v:.3f}" for k, v in best.items()))
        doc = analyse(load_scene(folder))
        print("\nhud-direct summary (design eye):")
        for k, v in doc["summary"]["design_eye"].items():
            print(f"  {k}: {v:.6g}" if isinstance(v, float) else f"  {k}: {v}")
        print("eyebox:")
        for k, v in doc["summary"]["eyebox"].items():
            print(f"  {k}: {v:.6g}" if isinstance(v, float) else f"  {k}: {v}")
        print("\nthe mirror's mesh against its exact ellipsoid (mesh - exact):")
        for section, block in doc["mesh_comparison"].items():
            for k, v in block.items():
                print(f"  {section}.{k}: exact {v['exact']:.6g}, mesh {v['mesh']:.6g}, error {v['error']:+.3g}")
        print("\nclosed forms (analysis, closed form, relative error):")
        for name, got, want, unit in closed_forms(tmp):
            rel = abs(got - want) / abs(want) if want else abs(got)
            print(f"  {name}: {got:.6g} {unit}, {want:.6g} {unit}, {rel:.2e}")
        zero, pts = wedge_zero(tmp)
        steps = [(round(w, 4), round(o, 4)) for w, o in pts]
        factor = hud_direct.VID / (hud_direct.VID - hud_direct.EYE_TO_WINDSHIELD)
        print(f"\nwedge: ghost offset 0 at {zero:.4f} mrad (secant steps {steps}); first order "
              f"{first_order_wedge_mrad():.4f} mrad, times VID / (VID - a) {first_order_wedge_mrad() * factor:.4f}; "
              f"preset {WEDGE_MRAD}")
        for name in ("hud-direct-wedge", "hud-direct-curved"):
            d = analyse(load_scene(PRESETS[name].write(tmp / name)), compare_mesh=False)
            s, b = d["summary"]["design_eye"], d["summary"]["eyebox"]
            print(f"{name}: VID {s['vid_mm']:.1f} mm, astigmatism {s['astigmatism_d']:.3f} D, static distortion "
                  f"{s['static_distortion_mrad']:.3f} mrad, ghost {s['ghost_separation_centre_arcmin']:.4f} arcmin "
                  f"(max {s['ghost_separation_arcmin']:.3f}); eyebox: dynamic {b['dynamic_distortion_mrad']:.3f}, "
                  f"convergence {b['convergence_mrad']:.3f}, divergence {b['divergence_mrad']:.3f}, dipvergence "
                  f"{b['dipvergence_mrad']:.3f} mrad, focus variation {b['focus_variation_d']:.3f} D, "
                  f"{b['eye_points_seeing_every_field_point']} eye points see every field point")
        if args.images is not None:
            args.images.mkdir(parents=True, exist_ok=True)
            for name, chart in (("distortion", distortion_chart), ("eyebox", eyebox_chart), ("vid", vid_chart)):
                from tracer.products.optics import clean

                write_png(args.images / f"hud-direct-optics-{name}.png", chart(clean(doc))[0])
            ghost_picture(tmp, args.images / "hud-direct-ghost-wedge.png")
            print(f"pictures written to {args.images}")


if __name__ == "__main__":
    main()
