"""Fingerprints of fixed-seed renders: the safety net of speed work.

    .venv/bin/python benchmarks/fingerprint.py [--rays N] [--seed K] [--polarisation off] [--save FILE | --compare FILE]

Renders every preset with every method variant (benchmarks/throughput.py's VARIANTS) for a budget in
rays with a fixed seed on one process, and prints the film's image mean and a SHA-256 of its sums.
A change that only makes the code faster must leave every fingerprint as it was (the same batches draw
the same numbers and add them in the same order); ``--compare`` says which differ, and by how much.
``--polarisation off`` writes every scene with ``"polarisation": "off"``: the unpolarised model of the
releases before polarisation, which must give their fingerprints (and so must scenes that nothing in
polarises, with the default).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.throughput import VARIANTS, make, set_polarisation  # noqa: E402
from presets import PRESETS, SINGLE_METHOD  # noqa: E402
from tracer.core.units import luminance  # noqa: E402
from tracer.methods import Budget  # noqa: E402
from tracer.runtime.allocator import keep_freed_memory  # noqa: E402
from tracer.scene import load_scene  # noqa: E402
from tracer.transport.world import World  # noqa: E402


def fingerprints(rays: int, seed: int, polarisation: str | None = None) -> dict:
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name in SINGLE_METHOD:
            folder = PRESETS[name].write(Path(tmp) / name)
            if polarisation is not None:
                set_polarisation(folder, polarisation)
            world = World(load_scene(folder))
            for variant in VARIANTS:
                res = make(world, variant, seed).render(Budget(rays=rays))
                h = hashlib.sha256()
                res.film.make_dense()  # the arrays over every pixel, as the fingerprints were first taken
                for k in sorted(res.film.kinds):
                    h.update(np.ascontiguousarray(res.film.sums[k]).tobytes())
                h.update(res.film.rep_sq.tobytes())
                out[f"{name} / {variant}"] = {"mean": float(luminance(res.film.rgb()).mean()), "rays": res.rays,
                                              "sha256": h.hexdigest()[:16]}
    return out


def main():
    keep_freed_memory()  # as the command line does (tracer/runtime/allocator.py)
    ap = argparse.ArgumentParser()
    ap.add_argument("--rays", type=int, default=1_500_000)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--polarisation", choices=("auto", "off"), help="the scenes' polarisation mode (their own: auto)")
    ap.add_argument("--save")
    ap.add_argument("--compare")
    args = ap.parse_args()
    now = fingerprints(args.rays, args.seed, args.polarisation)
    before = json.loads(Path(args.compare).read_text()) if args.compare else {}
    same = True
    for key, v in now.items():
        line = f"{key:40s} mean {v['mean']:.10g} rays {v['rays']:>10,} {v['sha256']}"
        if key in before:
            b = before[key]
            if b["sha256"] == v["sha256"]:
                line += "  same"
            else:
                same = False
                line += f"  DIFFERS (mean {b['mean']:.10g}, relative {v['mean'] / b['mean'] - 1:+.2e})"
        print(line, flush=True)
    if args.save:
        Path(args.save).write_text(json.dumps(now, indent=1))
    if args.compare:
        print("every fingerprint is the same" if same else "fingerprints differ")


if __name__ == "__main__":
    main()
