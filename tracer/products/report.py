"""report.json: the figures of a render (docs/user/report.md describes every field), and the readouts a
person reads off it (the command line's ``readouts``, Blender's HUD Readouts panel)."""

from __future__ import annotations

import json
import math

import numpy as np

from .. import __version__
from ..core.errors import EstimateOverflowError
from ..methods import INTEGRATORS, Budget, RenderResult
from ..scene import Scene

#: Median relative standard error of the lit pixels above which the report warns of noise.
NOISY = 0.5


def components_report(result: RenderResult) -> dict:
    """Each film component's share of the image, its mean luminance and that mean's standard error."""
    film = result.film
    totals = {k: film.component_totals(k) for k in film.kinds}  # (sum of Y, sum of its variance) over pixels
    total = sum(y for y, _ in totals.values())
    out = {}
    for name, kind in film.kinds.items():
        y, var = totals[name]
        count = film.norm[name]
        count = film.count_summary(name)[0] if isinstance(count, np.ndarray) else count  # per pixel: the mean
        out[name] = {"normalised_by": kind, "count": count, "mean_cd_m2": y / film.pixels,
                     "standard_error_cd_m2": math.sqrt(var) / film.pixels,
                     "share": y / total if total > 0 else 0.0}
    return out


def build_report(scene: Scene, result: RenderResult, figures: dict, shape: tuple[int, int], preview_info: dict,
                 budget: Budget, efficiency_definition: str = "") -> dict:
    """The figures of a render (report.json without its analysis: tracer.products.render.add_analysis).
    ``figures``: the image's luminance ``mean``, ``max`` and ``log_average`` (cd/m^2), and the
    ``median_relative_error`` of its lit pixels that hold the two samples an error needs (None where
    none does); ``shape`` (H, W)."""
    median_err = figures["median_relative_error"]
    warnings = list(result.warnings)
    if median_err is not None and median_err > NOISY:
        warnings.append(f"the image is dominated by noise: the median relative standard error of lit pixels is "
                        f"{median_err:.2f} at efficiency {result.efficiency:.3g}; give the method more rays or time"
                        f"{INTEGRATORS[result.method].noise_advice if result.method in INTEGRATORS else ''}")
    return {
        "tracer": f"hud-tracer {__version__}",
        "scene": {"name": scene.name, "folder": str(scene.root), "hash": scene.scene_hash},
        "method": result.method,
        "seed": result.seed,
        "budget": {"rays": budget.rays, "seconds": budget.seconds},
        "partial": result.partial,
        "rays": result.rays,
        "paths": result.paths,
        "paths_found_light": result.found,
        "batches": result.batches,
        "workers": result.extra.get("workers", 1),
        "seconds": result.seconds,
        "rays_per_second": result.rays_per_second,
        "efficiency": result.efficiency,
        "efficiency_definition": efficiency_definition,
        "luminance": {"unit": "cd/m^2", "mean": figures["mean"], "max": figures["max"],
                      "log_average": figures["log_average"],
                      "mean_standard_error": result.film.mean_standard_error(),
                      "mean_standard_error_from": result.film.mean_standard_error_basis()},
        "components": components_report(result),
        "replicates": result.film.replicates,
        "stage_seconds": result.stages,
        "adaptation_luminance": preview_info["adaptation_luminance"],
        "adaptation_mode": preview_info.get("adaptation_mode", "log_average"),
        "noise": {"median_relative_standard_error_lit_pixels": median_err,
                  "from": "each lit pixel's own samples (pixels with fewer than two left out)"},
        "preview": preview_info,
        "image": {"width": shape[1], "height": shape[0],
                  "channels": ["R", "G", "B", "Y", "Y_var"],
                  "pixel_mrad": [1000 * 2 * math.atan(math.tan(math.radians(scene.eye.fov_deg[i]) / 2)) /
                                 scene.eye.resolution[i] for i in range(2)]},
        "warnings": warnings,
        "method_details": result.extra,
        "brightness_theorem": None,
    }


#: The top-level keys of a render's report.json, in their order (a test checks every method's report
#: against it): what a sweep's ``--y`` and ``--require`` keys are checked against before any ray.
REPORT_SECTIONS = ("run_id", "tracer", "scene", "method", "seed", "budget", "partial", "rays", "paths",
                   "paths_found_light", "batches", "workers", "seconds", "rays_per_second", "efficiency",
                   "efficiency_definition", "luminance", "components", "replicates", "stage_seconds",
                   "adaptation_luminance", "adaptation_mode", "noise", "preview", "image", "warnings",
                   "method_details", "brightness_theorem", "polarisation", "hud", "optics", "analysis",
                   "analysis_seconds")


def finite_json(value, where: str = "report") -> str:
    """``value`` as JSON text; a NaN or infinite number (which JSON cannot hold) raises
    :class:`EstimateOverflowError` naming its key path."""
    def walk(v, path):
        if isinstance(v, float) and not math.isfinite(v):
            raise EstimateOverflowError(f"{where}: {path} is {v}: a value overflowed; the scene's luminances or "
                                        "fluxes are beyond what the outputs can hold")
        if isinstance(v, dict):
            for k, x in v.items():
                walk(x, f"{path}.{k}")
        elif isinstance(v, (list, tuple)):
            for i, x in enumerate(v):
                walk(x, f"{path}[{i}]")

    walk(value, "")
    return json.dumps(value, indent=2, allow_nan=False) + "\n"


def readouts(report: dict) -> list[tuple[str, str]]:
    """The figures of a render's report (tracer.products.report.build_report) as (label, text) rows, for a panel
    or a summary line: the HUD figures (symbols, background, contrast, the rear-projection spot), the
    windshield's ghost (from the brightness-theorem analysis), the luminance the eye adapts to, and how
    well the render converged (noise, efficiency, rays). Rows whose figures the report lacks (a
    stopped render skips the analysis) are left out."""
    rows: list[tuple[str, str]] = []
    hud = report.get("hud") or {}
    if "symbol_cd_m2" in hud:
        rows.append(("Symbols", f"{hud['symbol_cd_m2']:,.4g} cd/m²"))
        rows.append(("Background", f"{hud['background_cd_m2']:,.4g} cd/m²"))
        if "environment_behind_symbols_cd_m2" in hud:
            rows.append(("Behind the symbols", f"{hud['background_behind_symbols_cd_m2']:,.4g} cd/m² (environment "
                                               f"{hud['environment_behind_symbols_cd_m2']:,.4g})"))
        if hud["contrast_ratio"] is not None:
            rows.append(("Contrast (Ls + Lb) / Lb", f"{hud['contrast_ratio']:,.4g} : 1"))
    elif "display_cd_m2" in hud:
        rows.append(("Display", f"{hud['display_cd_m2']:,.4g} cd/m² ({hud.get('note', '')})"))
    elif hud.get("note"):
        rows.append(("Display", hud["note"]))
    spot = hud.get("spot")
    if spot:
        over = spot["peak_over_median_background"]  # None where the background's median is 0 (a noisy render)
        times = f"{over:.3g} x the background" if over is not None else "the background's median is 0"
        rows.append(("Spot", f"{spot['peak_cd_m2']:,.4g} cd/m², {times}, {spot['half_peak_diameter_deg']:.2g} deg"))
        if spot.get("contrast_against_environment") is not None:
            rows.append(("Spot against the environment", f"{spot['contrast_against_environment']:.4g} : 1 (environment "
                                                         f"{spot['environment_cd_m2']:,.4g} cd/m²)"))
    ghost = (report.get("brightness_theorem") or {}).get("ghost")
    if ghost and ghost.get("ratio_to_symbol") is not None:
        dx, dy = ghost["offset_px"]
        rows.append(("Ghost", f"{ghost['ratio_to_symbol']:.3g} of the symbols, {ghost['offset_mrad']:.3g} mrad "
                              f"({dx:+d}, {dy:+d} px)"))
    lum = report["luminance"]
    if lum.get("mean_standard_error_from", "replicates") == "none":  # 0 there means no error bar, not none
        rows.append(("Mean luminance", f"{lum['mean']:,.4g} cd/m² (no error bar: fewer than two samples)"))
    else:
        rows.append(("Mean luminance", f"{lum['mean']:,.4g} ± {lum['mean_standard_error']:.2g} cd/m²"))
    mode = report.get("adaptation_mode", "log_average").replace("_", "-")
    rows.append(("Adaptation", f"{report['adaptation_luminance']:,.4g} cd/m² ({mode})"))
    for name, ch in (report.get("method_details") or {}).get("channels", {}).items():
        rows.append((f"Channel {name}", f"{ch['method']} ({ch['chosen_by']}), {ch['mean_cd_m2']:,.4g} cd/m² mean"
                     if ch.get("method") else f"skipped: {ch['skipped']}"))
    noise = report["noise"]["median_relative_standard_error_lit_pixels"]
    if noise is not None:
        rows.append(("Noise", f"{100 * noise:.3g} % per lit pixel (median standard error)"))
    rows.append(("Efficiency", f"{report['efficiency']:.3g}"))
    rows.append(("Rays", f"{report['rays']:,} in {report['seconds']:.3g} s ({report['rays_per_second'] / 1e6:.3g} M/s, "
                         f"{report['workers']} process{'es' if report['workers'] > 1 else ''})"
                         + (", stopped early" if report["partial"] else "")))
    return rows


#: Units of report figures by the end of their name (the report names every physical quantity so).
UNIT_SUFFIXES = {"_cd_m2": "cd/m^2", "_deg": "deg", "_mm": "mm", "_mrad": "mrad", "_mm2": "mm^2", "_lm": "lm",
                 "_lx": "lx", "seconds": "s", "_px": "px", "_arcmin": "arcmin", "_percent": "%", "_d": "D"}
#: Units of figures whose names do not end in one.
UNITS = {"adaptation_luminance": "cd/m^2", "rays": "rays", "paths": "paths", "rays_per_second": "rays/s",
         "luminance.mean": "cd/m^2", "luminance.max": "cd/m^2", "luminance.log_average": "cd/m^2",
         "luminance.mean_standard_error": "cd/m^2"}


def report_unit(key: str) -> str:
    """The unit of the report figure at dotted ``key`` (``hud.symbol_cd_m2``: "cd/m^2"); "1" for ratios
    and shares."""
    if key in UNITS:
        return UNITS[key]
    last = key.rsplit(".", 1)[-1]
    return next((u for end, u in UNIT_SUFFIXES.items() if last.endswith(end)), "1")
