"""Speed against accuracy: relative RMSE against wall time for every preset and every method.

    .venv/bin/python benchmarks/convergence.py [--presets P ...] [--budgets 1 2 4 8 16] [--ref-seconds 120]

For each preset a high-sample reference image is rendered once and cached by scene hash in
benchmarks/cache/ (not committed): backward tracing with next-event estimation, the best unbiased
method where the scattering surfaces see the LEDs directly, or the photon method where they see them
only through glass (hud-screen, hud-direct-condenser: REFERENCE; its final radius leaves a blur that
counts in every method's error there), seed 1000 and up, on every core, for --ref-seconds (the
analytic scenes get a third of it). Then every method variant (forward; backward with next-event
estimation; backward without it, the paper's plain method; photon: benchmarks/throughput.py's
VARIANTS) renders at each budget in seconds (one process, seed = budget index), and the script
records wall time, rays, the method's own efficiency, the relative RMSE
against the reference over the whole image and over the bright region (pixels above 10 % of the
reference's 99th percentile: the symbols of hud-direct, the lit panel of analytic-mirror), with the
reference's own noise subtracted from the mean squared error, and the time efficiency
1 / (relative MSE x seconds). Output: benchmarks/results/<preset>.csv, docs/images/convergence-<preset>.png
(log-log, one line per method, slope -1/2 drawn through each method's first point) and
benchmarks/results/summary.md. benchmarks/mitsuba_peer.py adds Mitsuba 3's lines to the same CSVs,
charts and summary with the functions below (one metric implementation: :func:`errors`).
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.throughput import VARIANTS, make, set_polarisation  # noqa: E402
from presets import PRESETS, SINGLE_METHOD  # noqa: E402
from tracer.core.units import luminance  # noqa: E402
from tracer.methods import INTEGRATORS, Budget  # noqa: E402
from tracer.products import charts  # noqa: E402
from tracer.runtime.allocator import keep_freed_memory  # noqa: E402
from tracer.runtime.parallel import render_parallel  # noqa: E402
from tracer.scene import load_scene  # noqa: E402
from tracer.transport.world import World  # noqa: E402

CACHE = ROOT / "benchmarks" / "cache"
RESULTS = ROOT / "benchmarks" / "results"
DOCS = ROOT / "docs" / "images"
#: The reference's method: backward with next-event estimation, or for the presets named here the
#: photon method; and the presets that get the full --ref-seconds (the rest, closed-form scenes, a third).
REFERENCE_METHOD = "backward"
REFERENCE = {"hud-screen": "photon", "hud-screen-ideal-lcd": "photon", "hud-direct-condenser": "photon"}
FULL_REFERENCE = ("hud-direct", "hud-screen", "hud-screen-ideal-lcd", "hud-direct-condenser")
#: The accuracy at which the summary compares the methods' time (relative RMSE over the bright region).
TARGET_RMSE = 0.05
#: The paper's figure for hud-direct (sec. 4.2): forward 4 hours, backward 2 days.
PAPER_FORWARD_H, PAPER_BACKWARD_H = 4.0, 48.0


def reference(name: str, folder: Path, seconds: float, workers: int) -> dict:
    scene = load_scene(folder)
    method = REFERENCE.get(name, REFERENCE_METHOD)
    path = CACHE / f"{name}-{scene.scene_hash}-{method}-{seconds:g}s.npz"
    if path.is_file():
        data = np.load(path)
        return {k: data[k] for k in data.files}
    res = render_parallel(INTEGRATORS[method](scene, 1000), Budget(seconds=seconds), workers)
    y = luminance(res.film.rgb())
    ref = {"y": y, "var": res.film.variance_y(), "rays": np.array(res.rays), "method": np.array(method),
           "seconds": np.array(res.seconds)}
    CACHE.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, **ref)
    return ref


def scene_folder(name: str) -> Path:
    """The preset's scene folder in benchmarks/cache/scenes/, written on first use, with
    ``"polarisation": "off"``: these charts compare transport (methods, and Mitsuba's RGB variants,
    whose Fresnel is the unpolarised average) on one model of light; benchmarks/mitsuba_polarised.py
    compares the polarised model with Mitsuba's polarised variant."""
    folder = CACHE / "scenes" / name
    if not folder.exists():
        PRESETS[name].write(folder)
    return set_polarisation(folder, "off")


def reference_seconds(name: str, ref_seconds: float) -> float:
    """The reference's budget: ``ref_seconds`` for hud-direct, a third of it for the analytic scenes."""
    return ref_seconds if name in FULL_REFERENCE else ref_seconds / 3


def bright_region(y_ref: np.ndarray) -> np.ndarray:
    """Pixels above 10 % of the reference's 99th percentile (bool, the image's shape)."""
    return y_ref > 0.1 * np.percentile(y_ref, 99)


def errors(y: np.ndarray, ref: dict, wall: float) -> dict:
    """Relative RMSE of a luminance image ``y`` (cd/m^2) against the reference over the whole image and
    over the bright region, the reference's own variance subtracted from the mean squared error, and
    the time efficiency 1 / (relative MSE x ``wall`` seconds)."""
    y_ref, var_ref = ref["y"], ref["var"]
    region = bright_region(y_ref)
    row = {}
    for label, mask in (("image", np.ones_like(region)), ("region", region)):
        mean = float(y_ref[mask].mean())
        mse = max(float(np.mean((y[mask] - y_ref[mask]) ** 2) - np.mean(var_ref[mask])), 0.0)
        rel_mse = mse / mean**2
        row[f"rel_rmse_{label}"] = math.sqrt(rel_mse)
        row[f"time_efficiency_{label}"] = 1.0 / (rel_mse * wall) if rel_mse > 0 else math.inf
    return row


def measure(name: str, folder: Path, ref: dict, budgets: list[float]) -> list[dict]:
    world = World(load_scene(folder))
    region = bright_region(ref["y"])
    rows = []
    for method in VARIANTS:
        for k, seconds in enumerate(budgets):
            start = time.perf_counter()
            res = make(world, method, k).render(Budget(seconds=seconds))
            wall = time.perf_counter() - start
            y = luminance(res.film.rgb())
            row = {"preset": name, "method": method, "budget_s": seconds, "seconds": wall, "rays": res.rays,
                   "paths": res.paths, "method_efficiency": res.efficiency} | errors(y, ref, wall)
            row |= {"mean_image": float(y.mean()), "mean_region": float(y[region].mean()), "status": "ok"}
            rows.append(row)
            print(f"{name:17s} {method:9s} {seconds:5.1f} s  rays {res.rays:>11,}  rel RMSE image "
                  f"{row['rel_rmse_image']:.3g}  region {row['rel_rmse_region']:.3g}", flush=True)
    return rows


#: CSV columns: ours fill spp with nothing; status is "ok" or "cannot render: <why>" (not charted).
FIELDS = ["preset", "method", "budget_s", "seconds", "rays", "paths", "method_efficiency", "rel_rmse_image",
          "time_efficiency_image", "rel_rmse_region", "time_efficiency_region", "spp", "mean_image", "mean_region",
          "status"]


def write_rows(name: str, rows: list[dict]):
    """benchmarks/results/<name>.csv with :data:`FIELDS` (missing fields left empty)."""
    RESULTS.mkdir(parents=True, exist_ok=True)
    with open(RESULTS / f"{name}.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=FIELDS, restval="")
        w.writeheader()
        w.writerows(rows)


def read_rows(name: str) -> list[dict]:
    """The rows of benchmarks/results/<name>.csv, numbers as float, empty or missing fields as None (a CSV
    written before the status column charts every row)."""
    def value(text: str):
        if text == "":
            return None
        try:
            return float(text)
        except ValueError:
            return text

    with open(RESULTS / f"{name}.csv", newline="") as f:
        rows = [{k: value(r.get(k) or "") for k in FIELDS} for r in csv.DictReader(f)]
    return [r | {"status": r["status"] or "ok"} for r in rows]


def noise_floor(ref: dict) -> float:
    """The reference's own relative RMS noise per pixel: an error much below it cannot be measured (the
    subtraction of its variance then leaves noise, or 0)."""
    return math.sqrt(float(np.mean(ref["var"]))) / float(np.mean(ref["y"]))


def charted(row: dict) -> bool:
    return row["status"] == "ok" and row["rel_rmse_image"] > 0


def chart(name: str, rows: list[dict], ref: dict):
    """docs/images/convergence-<name>.png, in the charts' style (tracer.products.charts): one line per
    method in ``rows`` (in their order), rows that cannot render left out (named in the legend); the
    tracer's methods in solid lines, peers (Mitsuba) dashed with triangles; the reference's own noise as
    a horizontal line."""
    fig, _canvas = charts.new_figure(6.4, 4.4)
    ax = fig.add_subplot()
    charts.style(ax, log_x=True, log_y=True)
    methods = list(dict.fromkeys(x["method"] for x in rows))
    for i, method in enumerate(methods):
        r = [x for x in rows if x["method"] == method and charted(x)]
        if not r:
            black = [x for x in rows if x["method"] == method and x["status"].startswith("cannot render")]
            if black:
                ax.plot([], [], " ", label=f"{method}: cannot render (black)")
            continue
        t = np.array([x["seconds"] for x in r])
        e = np.array([x["rel_rmse_image"] for x in r])
        er = np.array([x["rel_rmse_region"] for x in r])
        color = f"C{i}"
        ours = method in VARIANTS
        ax.plot(t, e, "o-" if ours else "^--", color=color, label=f"{method}: whole image")
        ax.plot(t, er, "s:" if ours else "v:", color=color, label=f"{method}: bright region")
        ax.plot(t, e[0] * (t / t[0]) ** -0.5, "--", color="0.6", lw=0.8)
    ax.axhline(noise_floor(ref), color="0.5", ls="-.", lw=0.8, label="reference's own noise (whole image)")
    ax.set_xlabel(charts.label("wall time (one process, one thread)", "s"))
    ax.set_ylabel(charts.label("relative RMSE against the reference", "1"))
    ax.set_title(f"{name}: reference {str(ref['method'])} {float(ref['seconds']):.0f} s, "
                 f"{int(ref['rays']):,} rays; grey: slope -1/2", loc="left")
    ax.legend(fontsize=charts.FONT_PT - 2)
    fig.tight_layout()
    DOCS.mkdir(parents=True, exist_ok=True)
    fig.savefig(DOCS / f"convergence-{name}.png")


def summary_table(rows_by_preset: dict[str, list[dict]], budget: float) -> list[str]:
    """The summary's table: the last budget of every method of every preset; a method that cannot
    render shows its mean luminance against the reference's instead of errors."""
    lines = ["| preset | method | seconds | rays | rel. RMSE image | rel. RMSE bright region | "
             "1/(rel. MSE x s) image |", "|---|---|---|---|---|---|---|"]
    for name, rows in rows_by_preset.items():
        for r in rows:
            if r["budget_s"] != budget:
                continue
            rays = f"{int(r['rays']):,}" if r["rays"] is not None else f"- ({int(r['paths']):,} paths)"
            if r["status"] == "ok":
                lines.append(f"| {name} | {r['method']} | {r['seconds']:.1f} | {rays} | {r['rel_rmse_image']:.3g} | "
                             f"{r['rel_rmse_region']:.3g} | {r['time_efficiency_image']:.3g} |")
            else:
                lines.append(f"| {name} | {r['method']} | {r['seconds']:.1f} | {rays} | cannot render: mean "
                             f"{r['mean_image']:.3g} cd/m² | {r['mean_region']:.3g} cd/m² | - |")
    return lines


def forward_backward_note(rows_by_preset: dict[str, list[dict]], budget: float) -> list[str]:
    """hud-direct: forward against the paper's plain backward method on the symbols, beside the paper's
    figure, and backward with next-event estimation against both and against Mitsuba's path tracer."""
    last = {r["method"]: r for r in rows_by_preset.get("hud-direct", []) if r["budget_s"] == budget}
    lines = []
    if {"forward", "backward, no NEE"} <= set(last):
        ratio = last["forward"]["time_efficiency_region"] / last["backward, no NEE"]["time_efficiency_region"]
        lines.append(f"hud-direct, symbols: forward is {ratio:.0f} times as efficient as the paper's plain backward "
                     f"method (1/(MSE x time)); the paper: {PAPER_BACKWARD_H / PAPER_FORWARD_H:.0f} times the time "
                     "(4 hours against 2 days), i.e. 2-3 orders of magnitude in its words.")
    if {"forward", "backward"} <= set(last) and last["backward"]["status"] == "ok":
        ratio = last["backward"]["time_efficiency_image"] / last["forward"]["time_efficiency_image"]
        line = (f"hud-direct, whole image: backward with next-event estimation is {ratio:.0f} times as efficient as "
                f"forward (relative RMSE {last['backward']['rel_rmse_image']:.3g} against "
                f"{last['forward']['rel_rmse_image']:.3g} at {budget:g} s)")
        if "mitsuba-path" in last and last["mitsuba-path"]["status"] == "ok":
            line += (f"; Mitsuba's path tracer reaches {last['mitsuba-path']['rel_rmse_image']:.3g} in the same "
                     "time")
        lines.append(line + ".")
    return lines


def time_to_target(rows: list[dict], target: float = TARGET_RMSE) -> float | None:
    """Seconds a method needs for ``target`` relative RMSE over the bright region: the first budget that
    reaches it, interpolated on log-log axes from the one before, or, where none does, extrapolated
    from the last budget at slope -1/2 (noise falling as 1/sqrt(time); a method whose error is bias
    does better on the chart than this says). None where the method cannot render."""
    r = sorted((x for x in rows if charted(x)), key=lambda x: x["seconds"])
    if not r:
        return None
    for a, b in zip([None] + r[:-1], r, strict=True):
        if b["rel_rmse_region"] <= target:
            if a is None or a["rel_rmse_region"] <= target:
                return b["seconds"]
            s = math.log(target / a["rel_rmse_region"]) / math.log(b["rel_rmse_region"] / a["rel_rmse_region"])
            return a["seconds"] * (b["seconds"] / a["seconds"]) ** s
    last = r[-1]
    return last["seconds"] * (last["rel_rmse_region"] / target) ** 2


def target_note(rows_by_preset: dict[str, list[dict]], presets=("hud-screen", "hud-direct-condenser")) -> list[str]:
    """For the scenes whose scattering surfaces see the LEDs only through glass: each method's time to
    TARGET_RMSE on the bright region (the symbols), and how much sooner the best of ours gets there
    than the best other method and than Mitsuba's path tracer."""
    lines = []
    for name in presets:
        rows = rows_by_preset.get(name)
        if not rows:
            continue
        times = {m: time_to_target([r for r in rows if r["method"] == m])
                 for m in dict.fromkeys(r["method"] for r in rows)}
        known = {m: t for m, t in times.items() if t is not None}
        if not known:
            continue
        listing = ", ".join(f"{m} {t:.3g} s" if t is not None else f"{m} cannot render" for m, t in times.items())
        ours = {m: t for m, t in known.items() if m in VARIANTS}
        best = min(ours, key=ours.get)
        others = {m: t for m, t in known.items() if m != best}
        line = f"{name}, symbols: time to {TARGET_RMSE:.0%} relative RMSE: {listing}."
        if others:
            rival = min(others, key=others.get)
            line += f" {best} gets there {others[rival] / ours[best]:.3g} times sooner than the next best ({rival})"
            if "mitsuba-path" in known and rival != "mitsuba-path":
                line += f" and {known['mitsuba-path'] / ours[best]:.3g} times sooner than mitsuba-path"
            line += "."
        lines.append(line)
    return lines


def write_summary(presets: list[str], budget: float, sections: list[str] = ()) -> str:
    """benchmarks/results/summary.md from the presets' CSVs, with ``sections`` (Markdown) appended."""
    rows = {name: read_rows(name) for name in presets if (RESULTS / f"{name}.csv").is_file()}
    notes = forward_backward_note(rows, budget) + target_note(rows)
    text = "\n".join(summary_table(rows, budget)) + "\n\n" + "\n\n".join(notes) + "\n"
    for section in sections:
        text += "\n" + section.rstrip() + "\n"
    (RESULTS / "summary.md").write_text(text)
    return text


def main():
    keep_freed_memory()  # as the command line does (tracer/runtime/allocator.py)
    ap = argparse.ArgumentParser()
    ap.add_argument("--presets", nargs="*", default=list(SINGLE_METHOD))
    ap.add_argument("--budgets", type=float, nargs="*", default=[1, 2, 4, 8, 16])
    ap.add_argument("--ref-seconds", type=float, default=120.0)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    for name in args.presets:
        folder = scene_folder(name)
        ref = reference(name, folder, reference_seconds(name, args.ref_seconds), args.workers)
        rows = measure(name, folder, ref, args.budgets)
        write_rows(name, rows)
        chart(name, rows, ref)
    print(write_summary(list(SINGLE_METHOD), max(args.budgets)))


if __name__ == "__main__":
    main()
