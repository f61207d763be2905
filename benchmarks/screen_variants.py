"""The paper's Fig. 7: the HUD with a diffuse screen, with an LCD of absolute contrast (a) and of real
contrast, 300:1 (b), rendered with the photon method; the rear-projection spot and its numbers.

    .venv/bin/python benchmarks/screen_variants.py [--seconds 120] [--workers 2]

Renders hud-screen-ideal-lcd and hud-screen (every pixel, --seconds each, seed 1) and writes
docs/images/hud-screen-variants.png (the two previews one above the other, tone-mapped alike: Ward 1994 for
the eye adapted to the real-contrast image, and a second pair on a log scale over four decades below
the symbols, where the spot shows) and benchmarks/results/hud-screen-variants.md (the report's HUD
figures: symbols, background, contrast ratio, the spot's peak and size, and the method's figures).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from presets import PRESETS  # noqa: E402
from tracer.core.imageio import read_exr_channels, write_png  # noqa: E402
from tracer.core.units import luminance  # noqa: E402
from tracer.methods import Budget  # noqa: E402
from tracer.products.render import render_folder  # noqa: E402
from tracer.products.tonemap import adaptation_luminance, tonemap_ward  # noqa: E402

VARIANTS = (("hud-screen-ideal-lcd", "(a) LCD of absolute contrast"), ("hud-screen", "(b) LCD 300:1"))
#: The log view spans this many decades below the symbols' luminance.
DECADES = 4.0


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=120.0)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    images, reports = {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, _ in VARIANTS:
            folder = PRESETS[name].write(Path(tmp) / name)
            report, _ = render_folder(folder, "photon", Budget(seconds=args.seconds), 1, Path(tmp) / f"{name}-out",
                                      workers=args.workers)
            channels, _ = read_exr_channels(Path(tmp) / f"{name}-out" / "image.exr")
            images[name] = np.stack([channels[c] for c in "RGB"], axis=-1).astype(np.float64)
            reports[name] = report
            print(name, json.dumps(report["hud"]), flush=True)
    real = images["hud-screen"]
    y_real = luminance(real)
    adapt = adaptation_luminance(y_real)
    top = reports["hud-screen"]["hud"]["symbol_cd_m2"]
    rows = []
    for name, _ in VARIANTS:
        rows.append(tonemap_ward(images[name], adapt)[0])
    for name, _ in VARIANTS:
        y = luminance(images[name])
        v = np.clip((np.log10(np.maximum(y, 1e-30)) - np.log10(top) + DECADES) / DECADES, 0, 1)
        rows.append((np.repeat(v[..., None], 3, axis=2) * 255).astype(np.uint8))
    gap = np.full((4, real.shape[1], 3), 255, np.uint8)
    sheet = np.concatenate([x for r in rows for x in (r, gap)][:-1], axis=0)
    (ROOT / "docs" / "images").mkdir(parents=True, exist_ok=True)
    write_png(ROOT / "docs" / "images" / "hud-screen-variants.png", sheet)
    lines = ["| | symbols, cd/m² | background, cd/m² | CR = (Ls + Lb) / Lb | spot peak, cd/m² | spot / median "
             "background | spot size (half peak), deg | photons | rays | seconds |", "|---|---|---|---|---|---|---|---|"
             "---|---|"]
    for name, label in VARIANTS:
        h, r = reports[name]["hud"], reports[name]
        spot = h.get("spot") or {}
        cr = f"{h['contrast_ratio']:.4g}" if h.get("contrast_ratio") else "-"
        fmt = lambda v, f=".4g": format(v, f) if v is not None else "-"  # noqa: E731
        lines.append(f"| {label} ({name}) | {h['symbol_cd_m2']:.4g} | {h['background_cd_m2']:.3g} | {cr} | "
                     f"{fmt(spot.get('peak_cd_m2'), '.3g')} | {fmt(spot.get('peak_over_median_background'), '.3g')} | "
                     f"{fmt(spot.get('half_peak_diameter_deg'), '.3g')} | "
                     f"{r['method_details']['photon']['photons_emitted']:,} | {r['rays']:,} | {r['seconds']:.0f} |")
    text = "\n".join(lines) + "\n"
    (ROOT / "benchmarks" / "results").mkdir(parents=True, exist_ok=True)
    (ROOT / "benchmarks" / "results" / "hud-screen-variants.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
