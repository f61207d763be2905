"""hud-direct and its polarised variants (presets/hud_direct_polarised.py): symbol luminance and ghost
ratio of each, rendered and predicted, beside the closed forms at the windshield's 67 deg
(docs/results/polarisation.md).

    .venv/bin/python benchmarks/polarised_variants.py [--seconds S] [--workers W]

Each preset is rendered with ``hud-trace render NAME --method backward --seconds S --seed 1`` and its
report read: the symbol luminance (the mean over clear LCD cells) with its standard error, the
brightness-theorem analysis' prediction of it, and the analysis' ghost-to-symbol ratio. Closed forms
(Fresnel at 67 deg, n = 1.52, the mirror ideal): the primary image's windshield reflectance (Rs + Rp) / 2,
Rs or Rp, and the ghost ratio [(1-Rs)^2 Rs + (1-Rp)^2 Rp] / (Rs + Rp), (1 - Rs)^2 or (1 - Rp)^2. Writes
benchmarks/results/polarised_variants.md.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tracer.optics.polar import amplitudes  # noqa: E402

#: (preset, the light at the windshield).
VARIANTS = (("hud-direct", "unpolarised"), ("hud-direct-s", "s"), ("hud-direct-s-sunglasses", "s, analyser across"),
            ("hud-direct-film-sunglasses", "p (half-wave film), analyser along"))


def closed_forms(light: str) -> tuple[float, float]:
    """(windshield reflectance of the primary image, ghost ratio) at 67 deg; an ideal analyser across the
    light passes nothing."""
    rs, rp, _, _ = amplitudes([math.cos(math.radians(67.0))], 1.52)
    rs, rp = abs(rs[0]) ** 2, abs(rp[0]) ** 2
    if light == "unpolarised":
        return 0.5 * (rs + rp), ((1 - rs) ** 2 * rs + (1 - rp) ** 2 * rp) / (rs + rp)
    if light.startswith("s, analyser"):
        return 0.0, float("nan")
    if light.startswith("p"):
        return rp, (1 - rp) ** 2
    return rs, (1 - rs) ** 2


def _cd(v: float) -> str:
    """A luminance with its significant digits: 15,108, 8.3, 0.357."""
    return f"{v:,.0f}" if abs(v) >= 100 else f"{v:.3g}"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=30.0)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    rows = ["| preset | light at the windshield | symbols, rendered (± s.e.) | predicted | ghost / symbols | "
            "windshield R, closed form | ghost ratio, closed form |", "|---|---|---|---|---|---|---|"]
    with tempfile.TemporaryDirectory() as tmp:
        for name, light in VARIANTS:
            out = Path(tmp) / name
            subprocess.run([sys.executable, "-m", "tracer.cli", "render", name, "--method", "backward", "--seconds",
                            str(args.seconds), "--seed", "1", "--workers", str(args.workers), "--out", str(out)],
                           check=True, cwd=ROOT, stdout=subprocess.DEVNULL)
            bt = json.loads((out / "report.json").read_text())["brightness_theorem"]
            sym = bt["symbol"]
            ghost = (bt.get("ghost") or {}).get("ratio_to_symbol")
            r, g = closed_forms(light)
            blocked = math.isnan(g)  # the ghost of what is left is not a figure of the design
            rows.append(f"| {name} | {light} | {_cd(sym['rendered_cd_m2'])} ± {_cd(sym['standard_error_cd_m2'])} | "
                        f"{_cd(sym['predicted_cd_m2'])} | {'' if ghost is None or blocked else f'{ghost:.3f}'} | "
                        f"{r:.4f} | {'' if blocked else f'{g:.3f}'} |")
            print(rows[-1], flush=True)
    text = "\n".join(rows)
    out = ROOT / "benchmarks" / "results" / "polarised_variants.md"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(f"Made by `benchmarks/polarised_variants.py --seconds {args.seconds:g} --workers {args.workers}`."
                   f"\n\n{text}\n")
    print(text)


if __name__ == "__main__":
    main()
