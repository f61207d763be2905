"""Mitsuba 3 as a peer on the speed-against-accuracy charts (run after benchmarks/convergence.py).

    DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1 \\
        .venv/bin/python benchmarks/mitsuba_peer.py [--presets P ...] [--budgets 1 2 4 8 16] [--ref-seconds 120]

For every preset the scene is converted by benchmarks/mitsuba_scene.py (same geometry in mm, same
units, the module's docstring lists every mapping) and rendered with Mitsuba's ``path`` and
``ptracer`` integrators in the llvm variant on one Dr.Jit thread (``make bench`` installs Debian's
LLVM 19 for it; without it the scalar variant runs, slowly, and says so). Each integrator is warmed
up once (its first render traces and compiles the kernels: the compile time is reported, not timed),
then a pass size in samples per pixel is calibrated to take about PASS_SECONDS, and each budget of
wall time gets round(budget / pass time) passes, pass j of budget k with seed 1000 k + j. The
passes' mean image is measured exactly as the tracer's methods are (benchmarks/convergence.py,
``errors``: relative RMSE against the same cached reference, its own variance subtracted) and the
rows go into the same CSVs (methods "mitsuba-path", "mitsuba-ptracer"), charts and summary.

A render whose bright-region mean is below BLACK of the reference's is recorded as "cannot render"
(not charted): Mitsuba's particle tracer reaches the lens only by connecting a particle to it from an
emitter or a non-specular surface, so a scene that the eye sees only through specular (delta)
surfaces renders black.

Cross-check: the longest budget's mean luminance over the image and over the bright region, with a
standard error from the spread of its passes (batch means), against the reference's, whose standard
error is sqrt(sum of its pixel variances) / pixels; z is their difference over the combined error.
The cross-check's bright region is chosen by the same rule on the mean of Mitsuba's even passes and
measured on its odd passes and on the reference, so that neither measured image's noise selects the
pixels: on the reference's own region (the charts' "bright region", also in the table) the reference
reads high where it is noisy, since its noise lifts the pixels it selects. A render that cannot render
(or one of a single pass) is measured on the reference's region.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

from benchmarks import convergence as cv  # noqa: E402
from benchmarks import mitsuba_scene as ms  # noqa: E402
from benchmarks.mitsuba_checks import run_checks  # noqa: E402
from presets import SINGLE_METHOD  # noqa: E402
from tracer.core.units import luminance  # noqa: E402
from tracer.optics.bsdf import DELTA  # noqa: E402
from tracer.optics.materials import MATERIALS  # noqa: E402
from tracer.scene import Scene, load_scene  # noqa: E402

KINDS = ("path", "ptracer")
#: Target wall time of one pass, s.
PASS_SECONDS = 0.25
#: A render whose bright-region mean luminance is below this fraction of the reference's cannot render.
BLACK = 0.01


def render_passes(mi_scene, integrator, spp: int, seeds: list[int]) -> dict:
    """Passes of ``spp`` samples per pixel, one per seed: the luminance image (cd/m^2) of each pass, their
    mean, and the wall time (s) of them all."""
    passes = []
    start = time.perf_counter()
    for seed in seeds:
        passes.append(luminance(np.array(mi.render(mi_scene, integrator=integrator, spp=spp, seed=seed))))
    return {"passes": passes, "y": np.mean(passes, axis=0), "seconds": time.perf_counter() - start}


def warm_up(mi_scene, integrator) -> dict:
    """The first render (1 sample per pixel): its wall time and the kernels' code generation and LLVM
    compile time (Dr.Jit's kernel history; ``from_disk`` when Dr.Jit's kernel cache held them). Then
    the pass size: samples per pixel doubled until a pass takes PASS_SECONDS (the faster of two runs,
    since a new pass size may compile a kernel again)."""
    dr.kernel_history_clear()
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    first = render_passes(mi_scene, integrator, 1, [10**6])["seconds"]
    history = [k for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT]
    dr.set_flag(dr.JitFlag.KernelHistory, False)
    compile_ms = sum(k["codegen_time"] + k["backend_time"] for k in history)
    from_disk = sum(1 for k in history if k["cache_disk"])
    spp = 1
    while True:
        seconds = min(render_passes(mi_scene, integrator, spp, [10**6 + 2 * spp + i])["seconds"]
                      for i in range(2))
        if seconds >= PASS_SECONDS:
            break
        spp *= 2
    return {"first_render_s": first, "compile_s": compile_ms / 1e3, "kernels": len(history),
            "from_disk": from_disk, "spp": spp, "pass_s": seconds}


def cannot_render_reason(scene: Scene) -> str:
    delta = [o.name for o in scene.traced_objects if MATERIALS[o.material.type].flags & DELTA]
    return (f"cannot render: the eye sees every lit surface only through specular (delta) surfaces "
            f"({', '.join(delta)}), and a particle tracer cannot connect a particle to the lens through them")


def measure(name: str, scene: Scene, ref: dict, budgets: list[float]) -> tuple[list[dict], list[dict]]:
    """Mitsuba's rows for the CSV and, per integrator, what the summary reports of it."""
    region = cv.bright_region(ref["y"])
    t0 = time.perf_counter()
    mi_scene = ms.load(scene)
    load_s = time.perf_counter() - t0
    pixels = ref["y"].size
    rows, info = [], []
    for kind in KINDS:
        integrator = ms.integrator(scene, kind)
        warm = warm_up(mi_scene, integrator)
        kind_rows, last = [], None
        for k, budget in enumerate(budgets):
            passes = max(1, round(budget / warm["pass_s"]))
            last = render_passes(mi_scene, integrator, warm["spp"], [1000 * k + j for j in range(passes)])
            spp = warm["spp"] * passes
            row = {"preset": name, "method": f"mitsuba-{kind}", "budget_s": budget, "seconds": last["seconds"],
                   "rays": None, "paths": spp * pixels, "method_efficiency": None} | cv.errors(last["y"], ref,
                                                                                            last["seconds"])
            row |= {"spp": spp, "mean_image": float(last["y"].mean()), "mean_region": float(last["y"][region].mean()),
                    "status": "ok"}
            kind_rows.append(row)
            print(f"{name:17s} mitsuba-{kind:8s} {budget:5.1f} s  {passes:3d} passes x {warm['spp']} spp  "
                  f"{last['seconds']:6.2f} s  rel RMSE image {row['rel_rmse_image']:.3g}  "
                  f"region {row['rel_rmse_region']:.3g}", flush=True)
        if kind_rows[-1]["mean_region"] < BLACK * float(ref["y"][region].mean()):
            for row in kind_rows:
                row["status"] = cannot_render_reason(scene)
        rows += kind_rows
        info.append({"preset": name, "method": f"mitsuba-{kind}", "load_s": load_s, **warm,
                     "samples_per_s": kind_rows[-1]["paths"] / kind_rows[-1]["seconds"],
                     "status": kind_rows[-1]["status"], "ref_noise": cv.noise_floor(ref)}
                    | cross_check(last["passes"], ref, kind_rows[-1]["status"] == "ok"))
    return rows, info


def _mean_se(values: list[float]) -> tuple[float, float]:
    """Mean and its standard error from independent batches (nan with one batch)."""
    v = np.array(values)
    return float(v.mean()), float(v.std(ddof=1) / math.sqrt(len(v))) if len(v) > 1 else math.nan


def cross_check(passes: list[np.ndarray], ref: dict, renders: bool) -> dict:
    """Mean luminance (cd/m^2) and standard errors of Mitsuba's passes and of the reference over the image
    and over a bright region chosen on the even passes and measured on the odd ones (module docstring)."""
    split = renders and len(passes) > 1
    region = cv.bright_region(np.mean(passes[::2], axis=0) if split else ref["y"])
    measured = passes[1::2] if split else passes
    mean, se = _mean_se([float(y.mean()) for y in passes])
    mean_region, se_region = _mean_se([float(y[region].mean()) for y in measured])
    out = {"mean_image": mean, "se_image": se, "mean_region": mean_region, "se_region": se_region}
    pixels = ref["y"].size
    own = cv.bright_region(ref["y"])
    out |= {"own_region": float(np.mean(passes, axis=0)[own].mean()), "ref_own_region": float(ref["y"][own].mean())}
    return out | {"ref_image": float(ref["y"].mean()), "ref_se_image": math.sqrt(float(ref["var"].sum())) / pixels,
                  "ref_region": float(ref["y"][region].mean()),
                  "ref_se_region": math.sqrt(float(ref["var"][region].sum())) / int(region.sum())}


def _z(a: float, se_a: float, b: float, se_b: float) -> str:
    se = math.hypot(se_a, se_b)
    return f"{(a - b) / se:+.1f}" if se > 0 else "-"


def section(info: list[dict], checks: list[str], budget: float) -> str:
    """The summary's Mitsuba section (Markdown)."""
    lines = [f"## Mitsuba 3 (mitsuba {mi.__version__}, drjit {dr.__version__}, variant {ms.VARIANT}, one thread)", "",
             f"Cross-check, the {budget:g} s render of each Mitsuba integrator against our reference (mean luminance, "
             "cd/m², ± standard error; z = difference / combined error; the bright region chosen on Mitsuba's even "
             "passes and measured on its odd ones; last columns: on the reference's own bright region, which its "
             "noise selects):", "",
             "| preset | method | image: Mitsuba | image: ours | z | bright region: Mitsuba | bright region: ours | z "
             "| ref. region: Mitsuba | ref. region: ours |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in info:
        lines.append(f"| {r['preset']} | {r['method']} | {r['mean_image']:.5g} ± {r['se_image']:.2g} | "
                     f"{r['ref_image']:.5g} ± {r['ref_se_image']:.2g} | "
                     f"{_z(r['mean_image'], r['se_image'], r['ref_image'], r['ref_se_image'])} | "
                     f"{r['mean_region']:.5g} ± {r['se_region']:.2g} | "
                     f"{r['ref_region']:.5g} ± {r['ref_se_region']:.2g} | "
                     f"{_z(r['mean_region'], r['se_region'], r['ref_region'], r['ref_se_region'])} | "
                     f"{r['own_region']:.5g} | {r['ref_own_region']:.5g} |")
    noise = {r["preset"]: r["ref_noise"] for r in info}
    lines += ["", "The reference's own noise, relative RMS per pixel (a smaller error cannot be measured and shows "
              "as 0): " + ", ".join(f"{k} {v:.2g}" for k, v in noise.items()) + "."]
    lines += ["", "Speed and compile time (the first render traces and compiles the kernels; not in the timings):", "",
              "| preset | method | scene load, s | first render, s | compile, s (kernels, from disk cache) | "
              "pass, spp | samples/s |", "|---|---|---|---|---|---|---|"]
    for r in info:
        lines.append(f"| {r['preset']} | {r['method']} | {r['load_s']:.2f} | {r['first_render_s']:.2f} | "
                     f"{r['compile_s']:.2f} ({r['kernels']}, {r['from_disk']}) | {r['spp']} | "
                     f"{r['samples_per_s']:.3g} |")
    lines += [""] + [f"- {r['preset']}, {r['method']}: {r['status']}." for r in info if r["status"] != "ok"]
    lines += ["", "Checks of the mapping (benchmarks/mitsuba_checks.py):", ""] + checks
    return "\n".join(lines) + "\n"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--presets", nargs="*", default=list(SINGLE_METHOD))
    ap.add_argument("--budgets", type=float, nargs="*", default=[1, 2, 4, 8, 16])
    ap.add_argument("--ref-seconds", type=float, default=120.0)
    ap.add_argument("--workers", type=int, default=2, help="processes for a reference not in the cache")
    args = ap.parse_args()
    if ms.VARIANT != "llvm_ad_rgb":
        print("mitsuba_peer: DRJIT_LIBLLVM_PATH names no LLVM library: Mitsuba's scalar variant instead of llvm "
              "(slow: its Python plugins run per sample)", flush=True)
    info = []
    for name in args.presets:
        folder = cv.scene_folder(name)
        scene = load_scene(folder)
        ref = cv.reference(name, folder, cv.reference_seconds(name, args.ref_seconds), args.workers)
        rows, preset_info = measure(name, scene, ref, args.budgets)
        info += preset_info
        ours = [r for r in cv.read_rows(name) if not str(r["method"]).startswith("mitsuba-")]
        cv.write_rows(name, ours + rows)
        cv.chart(name, cv.read_rows(name), ref)
    checks = run_checks()
    print(cv.write_summary(list(SINGLE_METHOD), max(args.budgets), [section(info, checks, max(args.budgets))]))


if __name__ == "__main__":
    main()
