"""Stack PNG images vertically with a white gap between them (docs/images/studies.png).

    .venv/bin/python tools/stack_images.py OUT.png IN1.png IN2.png ... [--gap PX]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tracer.core.imageio import write_png  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("images", nargs="+")
    ap.add_argument("--gap", type=int, default=6, help="white rows between the images (default 6)")
    args = ap.parse_args()
    parts = []
    for path in args.images:
        buf = oiio.ImageBuf(path)
        if buf.has_error:
            sys.exit(f"stack_images: {path}: {buf.geterror()}")
        parts.append(np.asarray(buf.get_pixels(oiio.UINT8))[..., :3])
    widths = {p.shape[1] for p in parts}
    if len(widths) != 1:
        sys.exit(f"stack_images: the images differ in width: {sorted(widths)}")
    gap = np.full((args.gap, parts[0].shape[1], 3), 255, np.uint8)
    rows = [parts[0]]
    for p in parts[1:]:
        rows += [gap, p]
    write_png(args.out, np.concatenate(rows, axis=0))


if __name__ == "__main__":
    main()
