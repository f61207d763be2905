"""One render, start to finish: scene folder -> integrator -> image.exr, preview.png, report.json.

Output folder (checked and locked before the first ray; the three files are written after the render
as one set, each read back before it replaces its older version: tracer.products.outputs):

- image.exr: float32 channels R, G, B (apparent luminance, linear Rec.709, Y in cd/m^2), Y, and Y_var
  (variance of each pixel's Y estimate, (cd/m^2)^2); header metadata hud:method, hud:rays, ...
- preview.png: sRGB preview for an eye adapted to the view's log-average luminance (Ward 1994).
- report.json: the figures of :func:`build_report`.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
import uuid
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import __version__
from ..analysis.hud import erode, hud_figures
from ..core.errors import EstimateOverflowError, StoppedBeforeFirstBatch
from ..core.imageio import read_exr_channels, read_image, write_exr, write_png
from ..core.units import luminance
from ..methods import INTEGRATORS, Budget, RenderResult
from ..optics.pupil import pupil_diameter_mm
from ..runtime.parallel import render_parallel
from ..scene import Scene, load_scene
from ..transport.chains import ENV_SAMPLES, QUAD_TRUST, aim_coverage, specular_paths
from ..transport.world import World
from .outputs import OutputFile, OutputSet
from .tonemap import log_average_luminance, tonemap_ward

#: Median relative standard error of the lit pixels above which the report warns of noise.
NOISY = 0.5


def _mask_stats(y: np.ndarray, var: np.ndarray, idx: np.ndarray) -> dict:
    """Mean rendered Y over flat pixel indices and its standard error (independent pixels)."""
    k = len(idx)
    return {"pixels": int(k), "rendered_cd_m2": float(y[idx].mean()),
            "standard_error_cd_m2": float(math.sqrt(var[idx].sum()) / k)}


def _shift(a: np.ndarray, b: np.ndarray, max_shift: int = 25) -> tuple[int, int]:
    """Integer shift (dy, dx) that best overlays boolean grid ``b`` on ``a``."""
    best, arg = -1, (0, 0)
    for dy in range(-max_shift, max_shift + 1):
        for dx in range(-max_shift, max_shift + 1):
            score = int((a & np.roll(np.roll(b, dy, 0), dx, 1)).sum())
            if score > best:
                best, arg = score, (dy, dx)
    return arg


#: The pupil-integrated prediction: n x n stratified pupil points per pixel, on at most this many
#: evenly spaced pixels of each section.
PUPIL_GRID = 6
PUPIL_PIXELS = 128
#: A section's prediction is not comparable with the render when the light its scattering surfaces
#: receive through specular surfaces (not followed by the analysis) would add more than this share.
SPECULAR_SHARE = 0.01
#: Pupil fill (pupil-integrated over chief-ray prediction) outside 1 +- this is reported in the notes.
FILL_NOTE = 0.05
#: A comparable section rendered more than MISSING_SHARE below its prediction and more than
#: MISSING_SIGMA combined standard errors below it is reported as light the render missed (a normal
#: variate falls 5 sigma low 3 times in 10 million). Only a deficit is: the analysis leaves out light
#: scattered between diffuse surfaces, so a render may rightly exceed it.
MISSING_SHARE = 0.02
MISSING_SIGMA = 5.0
#: An aim that leaves more than this share of the light an object sends the eye outside its target is
#: reported to the methods that trace particles (the presets' aims cover 0.992 to 1).
AIM_COVERAGE = 0.98
#: Paths named in a section's breakdown; the rest are summed as "other paths".
BREAKDOWN_PATHS = 3


def _per_pixel(paths: list[dict], n: int) -> tuple[np.ndarray, list[np.ndarray], np.ndarray, np.ndarray]:
    """(total Y (n,), Y per path [(n,)], through-specular Y (n,), coarse Y (n,): the part of the total
    from lights closer than the quadrature resolves) summed per analysed pixel, cd/m^2."""
    total, through, coarse, per_path = np.zeros(n), np.zeros(n), np.zeros(n), []
    for p in paths:
        y = np.zeros(n)
        np.add.at(y, p["pixel"], luminance(p["luminance"]))
        np.add.at(through, p["pixel"], p["through_specular"])
        np.add.at(coarse, p["pixel"], p["coarse"])
        total += y
        per_path.append(y)
    return total, per_path, through, coarse


def _evenly(idx: np.ndarray, k: int) -> np.ndarray:
    """At most ``k`` entries of ``idx`` evenly spaced through it."""
    if len(idx) <= k:
        return idx
    return idx[np.unique(np.linspace(0, len(idx) - 1, k).round().astype(np.int64))]


def missing_light_warnings(analysis: dict, method: str) -> list[str]:
    """A warning for each comparable section of :func:`brightness_theorem` that the render puts more than
    MISSING_SHARE and MISSING_SIGMA combined standard errors below the prediction: light along specular
    chains that the render did not find, and that its error bars cannot show (a standard error from the
    replicates sees only the paths that were sampled). In forward tracing that is light reached through
    directions its aim leaves to the unaimed share: glass or a lens between an emitter and its aim
    target bends the aimed rays away from the target, so the light that does reach the eye arrives in
    rare heavy particles."""
    out = []
    for key in ("symbol", "background", "image"):
        entry = analysis.get(key)
        if not entry or entry.get("rendered_minus_predicted_sigma") is None:
            continue
        ratio, sigma = entry["rendered_over_predicted"], entry["rendered_minus_predicted_sigma"]
        if ratio < 1 - MISSING_SHARE and sigma < -MISSING_SIGMA:
            advice = (": light outside an emitter's aim (glass or a lens between it and its target bends the aimed "
                      "light off it) or high-order ghosts; render with the backward method, whose connections find "
                      "it, or aim at the target's image through the optics" if method in ("forward", "photon") else "")
            out.append(f"the {key} section renders {ratio:.3g} of the brightness-theorem prediction "
                       f"({entry['rendered_cd_m2']:.4g} against {entry['predicted_cd_m2']:.4g} cd/m^2, "
                       f"{-sigma:.3g} combined standard errors below it): the render misses light that reaches the "
                       f"eye through specular optics in paths too rare for its error bars to show{advice}")
    return out


def aim_warnings(analysis: dict) -> list[str]:
    """A warning for each aimed object of :func:`brightness_theorem`'s ``aim_coverage`` below
    AIM_COVERAGE: its particles' aimed share misses part of the light that reaches the eye from it."""
    return [f"the aim of {name} toward {c['target']} covers {100 * c['coverage']:.3g} % of the light that reaches "
            f"the eye from it (the analysis' rays over the pupil): particles find the rest only by its unaimed share, "
            f"rarely and heavily; aim at the target's image through the optics between them, or enlarge the target"
            for name, c in analysis.get("aim_coverage", {}).items() if c["coverage"] < AIM_COVERAGE]


#: The aims' coverage before the first ray (:func:`aim_preflight`): chains followed from at most this
#: many evenly spaced pixels of the image, each from PREFLIGHT_PUPIL_GRID^2 points over the pupil and
#: the pixel (0.6 s on analytic-disk, whose every chain ends in a quadrature of its emitter, 0.1 s on
#: hud-direct; the presets' figures as the report's, the glass block of tests/test_analysis.py 84.0 %
#: against 85.5 %).
PREFLIGHT_PIXELS = 64
PREFLIGHT_PUPIL_GRID = 4
#: The methods whose light paths follow the aims of emitters and scattering surfaces.
AIMED_METHODS = ("forward", "photon")


def aim_preflight(world: World, method: str, environment: bool = True) -> list[str]:
    """Before the first ray of a method that traces particles (:data:`AIMED_METHODS`), in a scene with
    aims: the aims' coverage (:func:`tracer.transport.chains.aim_coverage`) over the chains that the analysis
    follows from evenly spaced pixels of the whole image (the report's own figure, after the render,
    follows the sections' pixels), as :func:`aim_warnings` words it, so that an aim that leaves part of
    the light outside its target is known before a render is spent on rare heavy particles. Empty
    where every aim covers AIM_COVERAGE, and for other methods and scenes without aims."""
    aimed = any(o.material.aim is not None and o.material.aim.share > 0 for o in world.scene.objects) or any(
        o.emission is not None and o.emission.aim is not None and o.emission.aim.share > 0 for o in world.scene.objects)
    if method not in AIMED_METHODS or not aimed or world.accel is None:
        return []
    pixels = _evenly(np.arange(world.eye.width * world.eye.height), PREFLIGHT_PIXELS)
    ends = specular_paths(world, pixels=pixels, pupil_grid=PREFLIGHT_PUPIL_GRID, environment=environment)["ends"]
    return aim_warnings({"aim_coverage": aim_coverage(world, ends)})


def brightness_theorem(world: World, image_y: np.ndarray, var_y: np.ndarray, environment: bool = True) -> dict:
    """Compare the render with the brightness-theorem prediction of :mod:`tracer.transport.chains`.

    Sections come from the chief rays' dominant chain: "symbol" where its LCD cell is clear,
    "background" where it is black, or "image" (every pixel the chain reaches) where it has no LCD;
    all eroded by one grid cell, so edges blurred by the pupil are left out. Up to PUPIL_PIXELS
    evenly spaced pixels of each section are compared (``pixels``; the section has
    ``section_pixels``): the rendered mean over them against a prediction that follows each of them
    with PUPIL_GRID^2 rays from points over the pupil and the pixel (with its standard error)
    (``predicted_cd_m2``; the chief ray's alone is ``predicted_chief_ray_cd_m2``, their ratio
    ``pupil_fill``), and its breakdown by path sums to it ("other paths" included). ``environment``
    False (a method that does not render it) leaves the environment out of the prediction.

    A section is compared (``rendered_over_predicted``) only where the analysis' assumptions hold;
    otherwise ``valid`` is false and ``not_comparable`` says why: a scattering surface lit through
    specular surfaces (a condenser lens) whose light the analysis does not follow, or by a light
    closer than its quadrature resolves (a backlight right behind a screen).
    """
    res = specular_paths(world, environment=environment)
    grid_h, grid_w = res["grid"]
    pixels = res["pixels"]
    npts = len(pixels)
    total, per_path, _, _ = _per_pixel(res["paths"], npts)
    out: dict = {
        "method": "every specular branch followed from the pupil (chief rays for the path list; "
                  f"{PUPIL_GRID}x{PUPIL_GRID} points over the pupil for the sections); scattering surfaces lit "
                  "directly by the emitters (deterministic quadrature) and by the environment ("
                  f"{ENV_SAMPLES} directions from its own distribution per point); luminance = product of R and T "
                  "along the chain x luminance behind it" + ("" if environment else "; the environment left out, as "
                                                             "the method does not render it"),
        "assumptions": "light reaches scattering surfaces directly from the emitters and the environment, not "
                       "through specular optics, and from no light closer than the quadrature resolves",
        "grid_stride_px": res["stride"],
        "valid": True,
        "not_comparable": [],
        "notes": [],
        "paths": [],
    }
    y_img = image_y.reshape(-1)
    v_img = var_y.reshape(-1)
    for p, y in zip(res["paths"][:8], per_path[:8], strict=True):
        out["paths"].append({"path": p["path"], "pixels_fraction": float(len(np.unique(p["pixel"])) / npts),
                             "predicted_mean_cd_m2": float(y.mean()),
                             "transfer_factor_mean": float(p["factor"].mean())})
    if len(res["paths"]) > 8:
        out["paths"].append({"path": "other paths", "predicted_mean_cd_m2": float(sum(y.mean() for y in per_path[8:]))})
    if not res["paths"]:
        return out
    lcd_paths = [p for p in res["paths"] if np.any(np.isfinite(p["lcd"]))]
    masks = {}
    grid_lcd = None
    if lcd_paths:
        main = lcd_paths[0]
        grid_lcd = np.full(npts, np.nan)
        grid_lcd[main["pixel"]] = main["lcd"]
        grid_lcd = grid_lcd.reshape(grid_h, grid_w)
        masks["symbol"] = erode(grid_lcd >= 0.5)
        # Background: black on the dominant chain and on the next one through the LCD (the ghost), so
        # that the ghost's symbols do not count as black leak. NaN compares False: off the LCD is neither.
        background = grid_lcd < 0.5
        for p in lcd_paths[1:2]:
            other = np.full(npts, np.nan)
            other[p["pixel"]] = p["lcd"]
            background &= ~(other.reshape(grid_h, grid_w) >= 0.5)
        masks["background"] = erode(background)
    else:
        reached = np.zeros(npts, bool)
        reached[res["paths"][0]["pixel"]] = True
        masks["image"] = erode(reached.reshape(grid_h, grid_w))
        out["image_path"] = res["paths"][0]["path"]
    blockers = dict(res["specular_blockers"])
    ends = []  # where the sections' pupil rays end, for the aims' coverage
    for key, mask in masks.items():
        idx = np.nonzero(mask.ravel())[0]
        if len(idx) == 0:
            continue
        sel = _evenly(idx, PUPIL_PIXELS)
        pup = specular_paths(world, pixels=pixels[sel], pupil_grid=PUPIL_GRID, environment=environment)
        for k, v in pup["specular_blockers"].items():
            blockers[k] = sorted(set(blockers.get(k, [])) | set(v))
        ends += pup["ends"]
        p_total, p_per_path, p_through, p_coarse = _per_pixel(pup["paths"], len(sel))
        entry = _mask_stats(y_img, v_img, pixels[sel])  # the rendered pixels the prediction is made for
        entry["section_pixels"] = int(len(idx))
        pred = float(p_total.mean())
        # The prediction's own sampling error: each pixel's mean of its n^2 rays (the stratified
        # variance is at most this estimate).
        n2 = pup["pupil_samples"]
        per_ray = np.zeros(len(sel) * n2)
        for p in pup["paths"]:
            np.add.at(per_ray, p["ray"], luminance(p["luminance"]) * n2)
        var_pixel = per_ray.reshape(len(sel), n2).var(axis=1, ddof=1) / n2
        entry["predicted_standard_error_cd_m2"] = float(math.sqrt(var_pixel.sum()) / len(sel))
        chief = float(total[sel].mean())
        entry["predicted_cd_m2"] = pred
        entry["predicted_chief_ray_cd_m2"] = chief
        entry["pupil_fill"] = pred / chief if chief > 0 else None
        named = {p["path"]: float(y.mean()) for p, y in zip(pup["paths"][:BREAKDOWN_PATHS],
                                                            p_per_path[:BREAKDOWN_PATHS], strict=True)}
        if len(pup["paths"]) > BREAKDOWN_PATHS:
            named["other paths"] = float(sum(y.mean() for y in p_per_path[BREAKDOWN_PATHS:]))
        entry["predicted_by_path_cd_m2"] = named
        through = float(p_through.mean())
        entry["through_specular_cd_m2"] = through
        reasons = []
        if through > SPECULAR_SHARE * (pred + through):
            lit = ", ".join(f"{s} (through {', '.join(b)})" for s, b in sorted(blockers.items()))
            reasons.append(f"{key}: scattering surfaces are lit through specular optics the analysis does not follow: "
                           f"{lit}; direct light would add {through:.4g} cd/m^2 to the {pred:.4g} predicted, so the "
                           "prediction is a lower bound")
        coarse_y = float(p_coarse.mean())
        if coarse_y > SPECULAR_SHARE * pred:
            reasons.append(f"{key}: {coarse_y:.4g} of the {pred:.4g} cd/m^2 predicted comes from lights closer to the "
                           "scattering surfaces than the analysis' quadrature resolves (cells larger than "
                           f"{QUAD_TRUST:g} x their distance: a large light right behind a screen or diffuser), so "
                           "the prediction is not reliable there")
        if entry["pupil_fill"] is not None and abs(entry["pupil_fill"] - 1) > FILL_NOTE:
            out["notes"].append(f"{key}: what the chief ray sees fills {100 * entry['pupil_fill']:.3g} % of the pupil "
                                f"as seen through the optics: the chief ray alone would predict {chief:.4g} cd/m^2, "
                                f"the pupil average is {pred:.4g}")
        entry["valid"] = not reasons
        entry["rendered_over_predicted"] = entry["rendered_cd_m2"] / pred if pred > 0 and not reasons else None
        combined = math.hypot(entry["standard_error_cd_m2"], entry["predicted_standard_error_cd_m2"])
        entry["rendered_minus_predicted_sigma"] = ((entry["rendered_cd_m2"] - pred) / combined
                                                   if combined > 0 and entry["rendered_over_predicted"] is not None
                                                   else None)
        out["not_comparable"] += reasons
        out[key] = entry
    out["valid"] = not out["not_comparable"]
    out["aim_coverage"] = aim_coverage(world, ends)
    if lcd_paths:
        out["lcd_contrast_ratio"] = next(o.material.params["contrast_ratio"] for o in world.scene.objects
                                         if o.material.type == "lcd")
        if "symbol" in out and "background" in out:
            out["symbol_over_contrast_ratio_cd_m2"] = out["symbol"]["rendered_cd_m2"] / out["lcd_contrast_ratio"]
            out["rendered_contrast"] = (out["symbol"]["rendered_cd_m2"] / out["background"]["rendered_cd_m2"]
                                        if out["background"]["rendered_cd_m2"] > 0 else None)
    if len(lcd_paths) > 1:
        main, ghost = lcd_paths[0], lcd_paths[1]
        main_y = luminance(main["luminance"])
        ghost_y = luminance(ghost["luminance"])
        g_lcd = np.full(npts, np.nan)
        g_lcd[ghost["pixel"]] = ghost["lcd"]
        g_open = (g_lcd >= 0.5).reshape(grid_h, grid_w)
        dy, dx = _shift(grid_lcd >= 0.5, g_open)
        eye = world.eye
        px_mrad = 1000 * 2 * math.atan(eye.half_x / eye.focal) / eye.width
        g_sel = np.isin(ghost["pixel"], np.nonzero(g_lcd >= 0.5)[0])
        m_sel = np.isin(main["pixel"], np.nonzero(grid_lcd.ravel() >= 0.5)[0])
        g_mean = float(ghost_y[g_sel].mean()) if g_sel.any() else 0.0
        m_mean = float(main_y[m_sel].mean()) if m_sel.any() else 0.0
        out["ghost"] = {
            "path": ghost["path"],
            "predicted_cd_m2": g_mean,
            "ratio_to_symbol": g_mean / m_mean if m_mean > 0 else None,
            "offset_px": [-dx * res["stride"], -dy * res["stride"]],
            "offset_mrad": float(math.hypot(dx, dy) * res["stride"] * px_mrad),
        }
    return out


def adaptation_luminance(y: np.ndarray, mode: str = "log_average") -> float:
    """The luminance (cd/m^2) the eye adapts to, over the pixels that receive light: their log-average
    (``mode`` "log_average", Ward 1994 and Reinhard et al. 2002, eq. 1) or their arithmetic mean
    ("mean", the "average luminance" of the paper, sec. 4.1). Pixels that receive none (no environment,
    nothing in view) are left out: an eye looking at a HUD in the dark adapts to what it sees, not to
    an infinitely dark void. The log-average weighs a bright sun or HUD symbol less than the mean."""
    lit = y > 1e-9 * max(float(y.max()), 1e-300)
    if mode == "mean":
        return float(y[lit].mean()) if lit.any() else 0.0
    return log_average_luminance(y[lit]) if lit.any() else log_average_luminance(y)


def components_report(result: RenderResult) -> dict:
    """Each film component's share of the image, its mean luminance and that mean's standard error."""
    film = result.film
    out = {}
    total = float(luminance(film.rgb()).sum())
    for name, kind in film.kinds.items():
        y = luminance(film.component_rgb(name))
        var = film.component_variance_y(name)
        out[name] = {"normalised_by": kind, "count": film.norm[name], "mean_cd_m2": float(y.mean()),
                     "standard_error_cd_m2": float(math.sqrt(var.sum()) / y.size),
                     "share": float(y.sum()) / total if total > 0 else 0.0}
    return out


def build_report(scene: Scene, result: RenderResult, image: np.ndarray, var_y: np.ndarray, preview_info: dict,
                 budget: Budget, analysis: dict | None, efficiency_definition: str = "") -> dict:
    y = luminance(image)
    rel_err = np.sqrt(var_y) / np.maximum(y, 1e-300)
    lit = y > 1e-6 * max(float(y.max()), 1e-300)
    median_err = float(np.median(rel_err[lit])) if lit.any() else None
    warnings = list(result.warnings)
    if median_err is not None and median_err > NOISY:
        warnings.append(f"the image is dominated by noise: the median relative standard error of lit pixels is "
                        f"{median_err:.2f} at efficiency {result.efficiency:.3g}; give the method more rays or time"
                        f"{INTEGRATORS[result.method].noise_advice if result.method in INTEGRATORS else ''}")
    if analysis is not None:
        warnings += [f"brightness theorem not compared: {r}" for r in analysis["not_comparable"]]
        warnings += missing_light_warnings(analysis, result.method)
        if result.method in ("forward", "photon"):
            warnings += aim_warnings(analysis)
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
        "luminance": {"unit": "cd/m^2", "mean": float(y.mean()), "max": float(y.max()),
                      "log_average": log_average_luminance(y),
                      "mean_standard_error": result.film.mean_standard_error()},
        "components": components_report(result),
        "replicates": result.film.replicates,
        "stage_seconds": result.stages,
        "adaptation_luminance": preview_info["adaptation_luminance"],
        "adaptation_mode": preview_info.get("adaptation_mode", "log_average"),
        "noise": {"median_relative_standard_error_lit_pixels": median_err},
        "preview": preview_info,
        "image": {"width": image.shape[1], "height": image.shape[0],
                  "channels": ["R", "G", "B", "Y", "Y_var"],
                  "pixel_mrad": [1000 * 2 * math.atan(math.tan(math.radians(scene.eye.fov_deg[i]) / 2)) /
                                 scene.eye.resolution[i] for i in range(2)]},
        "warnings": warnings,
        "method_details": result.extra,
        "brightness_theorem": analysis,
    }


#: The top-level keys of a render's report.json, in their order (a test checks every method's report
#: against it): what a sweep's ``--y`` and ``--require`` keys are checked against before any ray.
REPORT_SECTIONS = ("run_id", "tracer", "scene", "method", "seed", "budget", "partial", "rays", "paths",
                   "paths_found_light", "batches", "workers", "seconds", "rays_per_second", "efficiency",
                   "efficiency_definition", "luminance", "components", "replicates", "stage_seconds",
                   "adaptation_luminance", "adaptation_mode", "noise", "preview", "image", "warnings",
                   "method_details", "brightness_theorem", "polarisation", "hud")

#: The files of a render, written as a set (tracer.products.outputs).
OUTPUT_NAMES = ("image.exr", "preview.png", "report.json")


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


def _finite_channels(channels: dict[str, np.ndarray]):
    """Raise :class:`EstimateOverflowError` if a channel, as float32, holds NaN or Inf."""
    for name, c in channels.items():
        c32 = np.asarray(c, dtype=np.float32)
        if not np.all(np.isfinite(c32)):
            biggest = float(np.nanmax(np.abs(np.asarray(c, dtype=np.float64))))
            raise EstimateOverflowError(f"image.exr: channel {name} does not fit in float32 (largest |value| "
                                        f"{biggest:.3g}): the scene's luminances or fluxes are too large")


def output_files(channels: dict[str, np.ndarray], attrs: dict, preview: np.ndarray, report: dict) -> list[OutputFile]:
    """The render's three files, each with its read-back check."""
    _finite_channels(channels)
    report_text = finite_json(report)
    planes = {k: np.asarray(v, dtype=np.float32) for k, v in channels.items()}

    def check_exr(path):
        got, got_attrs = read_exr_channels(path)
        if set(got) != set(planes) or any(not np.array_equal(got[k], planes[k]) for k in planes):
            raise ValueError("the pixels read back differ from those written")
        if got_attrs.get("hud:run_id") != attrs["hud:run_id"]:
            raise ValueError("the header read back differs from the one written")

    def check_png(path):
        if read_image(path).shape[:2] != preview.shape[:2]:
            raise ValueError("the preview read back has another size")

    def check_report(path):
        if json.loads(Path(path).read_text())["run_id"] != report["run_id"]:
            raise ValueError("the report read back differs from the one written")

    return [OutputFile("image.exr", lambda p: write_exr(p, channels, attrs), check_exr),
            OutputFile("preview.png", lambda p: write_png(p, preview), check_png),
            OutputFile("report.json", lambda p: Path(p).write_text(report_text), check_report)]


#: Share of the budget of the pilot render that finds the adaptation luminance a pupil follows.
PUPIL_PILOT_SHARE = 0.05


def _check_started(result: RenderResult):
    """StoppedBeforeFirstBatch for a render that ``should_stop`` ended before any batch was merged."""
    if result.partial and result.batches == 0:
        raise StoppedBeforeFirstBatch(f"stopped after {result.seconds:.1f} s, before the first batch ended")


def _follow_pupil(integrator, budget: Budget, workers: int, should_stop):
    """For an eye whose pupil follows the image (EyeSpec.pupil_from_image): a pilot render of a share
    of the budget (backward tracing of every source: the adaptation luminance is a mean over the image,
    which it finds fast in every scene) gives the adaptation luminance, Watson & Yellott's formula the
    pupil (pupil.py); the integrator is rebuilt for that eye and the budget left is returned with what
    the pilot found. (Apparent luminance hardly depends on the pupil, so one pilot is enough.) Raises
    :class:`~tracer.core.errors.StoppedBeforeFirstBatch` when ``should_stop`` ends the pilot before its first
    batch: there is no luminance to adapt to."""
    spec = integrator.eye.spec
    share = Budget(rays=None if budget.rays is None else max(1, int(PUPIL_PILOT_SHARE * budget.rays)),
                   seconds=None if budget.seconds is None else PUPIL_PILOT_SHARE * budget.seconds)
    t0 = time.perf_counter()
    pilot = INTEGRATORS["backward"](integrator.world, integrator.seed + 1)
    first = pilot.render(share, None, should_stop)
    _check_started(first)
    adapt = adaptation_luminance(luminance(first.film.rgb()), spec.adaptation)
    pupil = pupil_diameter_mm(adapt, age_years=spec.observer_age)
    eye = dataclasses.replace(spec, pupil_diameter_mm=pupil)
    world = integrator.world.with_eye(eye)
    rebuilt = type(integrator)(world, integrator.seed, None if integrator.auto_batch else integrator.batch_size,
                               integrator.opts)
    rebuilt.notice = integrator.notice
    left = Budget(rays=None if budget.rays is None else max(1, budget.rays - first.rays),
                  seconds=None if budget.seconds is None else max(1e-3, budget.seconds - (time.perf_counter() - t0)))
    found = {"pilot_rays": first.rays, "pilot_seconds": first.seconds, "adaptation_mode": spec.adaptation,
             "pilot_adaptation_luminance_cd_m2": adapt, "pupil_diameter_mm": pupil,
             "first_guess_pupil_diameter_mm": spec.pupil_diameter_mm,
             "formula": "Watson & Yellott 2012, doi:10.1167/12.10.12 (60 deg field, both eyes)"}
    return rebuilt, left, found


def run_render(integrator, budget: Budget, workers: int = 1, progress=None, should_stop=None,
               preview=None) -> tuple[object, RenderResult]:
    """Run ``integrator`` for ``budget`` on ``workers`` processes (tracer.runtime.parallel) or in this one:
    the command line's render and Blender's, with the two callables of the seam (``progress``,
    ``should_stop``) and the optional ``preview(film)`` (tracer.methods.base.drive). Where the eye's
    pupil follows the image, a pilot finds it first (:func:`_follow_pupil`). Returns the integrator that
    rendered (rebuilt for that pupil) and the result. Raises
    :class:`~tracer.core.errors.StoppedBeforeFirstBatch` when ``should_stop`` ended the render before its
    first batch (there is no estimate, and a black image would read as a scene without light), and
    FloatingPointError if the estimate holds NaN or Inf (a bug: the estimators never make them)."""
    pupil = None
    if integrator.eye.spec.pupil_from_image:
        integrator, budget, pupil = _follow_pupil(integrator, budget, workers, should_stop)
    if workers > 1:
        result = render_parallel(integrator, budget, workers, progress, should_stop, preview)
    else:
        result = integrator.render(budget, progress, should_stop, preview)
    _check_started(result)
    if pupil is not None:
        result.extra["pupil"] = pupil
    if not (np.all(np.isfinite(result.film.rgb())) and np.all(np.isfinite(result.film.variance_y()))):
        raise FloatingPointError("the estimator produced NaN or Inf: this is a bug, please report the scene")
    return integrator, result


@dataclass
class Products:
    """What a render gives its user, the same from the command line and from Blender: the image
    (H, W, 3) cd/m^2 linear Rec.709, Y and its variance (H, W), the preview (sRGB uint8, Ward 1994),
    the report (:func:`build_report`, with ``run_id``), the EXR's channels and header attributes
    (``hud:*``). ``files()`` are the command line's three output files."""

    image: np.ndarray
    y: np.ndarray
    var_y: np.ndarray
    preview: np.ndarray
    report: dict
    channels: dict
    attrs: dict

    def files(self) -> list[OutputFile]:
        return output_files(self.channels, self.attrs, self.preview, self.report)


def render_products(world: World, integrator, result: RenderResult, budget: Budget, analyse: bool = True) -> Products:
    """The image, report and EXR contents of a finished render (see :class:`Products`). The
    brightness-theorem analysis and the HUD figures run unless ``analyse`` is false or the render was
    stopped early (``result.partial``: a stop must end promptly); their time is not part of the budget.
    An image made of channels (the hybrid method: film groups) also gets each channel as EXR layer
    ``<channel>.R, .G, .B, .Y, .Y_var``, and its HUD figures read the symbols off the HUD channel and
    the background behind them off the environment channel."""
    scene = world.scene
    film = result.film
    image = film.rgb()
    var_y = film.variance_y()
    y = luminance(image)
    mode = world.eye.spec.adaptation
    preview, info = tonemap_ward(image, adaptation_luminance(y, mode))
    info["adaptation_mode"] = mode
    channels_y = {g: luminance(film.rgb(g)) for g in film.groups if g}
    analysis = figures = None
    if analyse and world.accel is not None and not result.partial:
        t0 = time.perf_counter()
        analysis = brightness_theorem(world, y, var_y, integrator.renders_environment)
        analysis["seconds"] = time.perf_counter() - t0
        figures = hud_figures(world, channels_y["hud"], channels_y.get("environment")) if "hud" in channels_y \
            else hud_figures(world, y)
    report = build_report(scene, result, image, var_y, info, budget, analysis, integrator.efficiency_definition)
    report["polarisation"] = world.polarisation_report()
    report["hud"] = figures
    run_id = uuid.uuid4().hex
    report = {"run_id": run_id} | report
    attrs = {"hud:method": result.method, "hud:rays": str(result.rays), "hud:paths": str(result.paths),
             "hud:seconds": float(result.seconds), "hud:efficiency": float(result.efficiency),
             "hud:seed": str(result.seed), "hud:scene_hash": scene.scene_hash, "hud:partial": int(result.partial),
             "hud:run_id": run_id,
             "hud:units": "R,G,B,Y: apparent luminance cd/m^2 (Rec.709, Y=0.2126R+0.7152G+0.0722B); "
                          "Y_var: (cd/m^2)^2" + ("; <channel>.R,G,B,Y,Y_var: the same for each channel"
                                                 if channels_y else "")}
    channels = {"R": image[..., 0], "G": image[..., 1], "B": image[..., 2], "Y": y, "Y_var": var_y}
    for g in channels_y:
        rgb = film.rgb(g)
        channels |= {f"{g}.R": rgb[..., 0], f"{g}.G": rgb[..., 1], f"{g}.B": rgb[..., 2], f"{g}.Y": channels_y[g],
                     f"{g}.Y_var": film.variance_y(g)}
    report["image"]["channels"] = list(channels)
    return Products(image, y, var_y, preview, report, channels, attrs)


def render_scene(scene: Scene, method: str, budget: Budget, seed: int, out_dir: str | Path,
                 progress=None, should_stop=None, batch_size: int | None = None, analyse: bool = True,
                 workers: int = 1, notice=None):
    """Render ``scene`` with ``method`` into ``out_dir`` (on ``workers`` processes); returns
    (report dict, RenderResult). ``notice(message)``, where given, hears the warnings that can be
    given before the first ray (:func:`aim_preflight`; the report repeats them from its own analysis)
    and those the method finds before its first batch (``Integrator.warn_early``).

    The output folder is checked and locked before the first ray (:class:`tracer.products.outputs.OutputSet`:
    :class:`~tracer.products.outputs.OutputFolderError` if it cannot take the outputs), and image.exr,
    preview.png and report.json are written as a set after the render
    (:class:`~tracer.products.outputs.OutputWriteError` if that fails; the earlier outputs are then kept). They
    share a run id (``report["run_id"]``, the EXR attribute ``hud:run_id``). A partial render (stopped
    through ``should_stop``) skips the brightness-theorem analysis, so that it ends promptly; one stopped
    before its first batch ended has nothing to write and raises
    :class:`~tracer.core.errors.StoppedBeforeFirstBatch` (the folder keeps its earlier outputs)."""
    if method not in INTEGRATORS:
        raise ValueError(f"unknown method {method!r} (known: {', '.join(INTEGRATORS)})")
    outputs = OutputSet(out_dir, OUTPUT_NAMES, scene_root=scene.root).open()
    try:
        world = World(scene)
        integrator = INTEGRATORS[method](world, seed, batch_size)
        if notice is not None:
            for w in aim_preflight(world, method, integrator.renders_environment):
                notice(f"before the first ray: {w}")
            integrator.notice = notice
        integrator, result = run_render(integrator, budget, workers, progress, should_stop)
        products = render_products(integrator.world, integrator, result, budget, analyse)
        outputs.commit(products.files())
        outputs.keep()
    finally:
        outputs.close()
    return products.report, result


def render_folder(scene_dir, method, budget, seed, out_dir, **kw):
    """Load a scene folder and render it (see :func:`render_scene`)."""
    return render_scene(load_scene(scene_dir), method, budget, seed, out_dir, **kw)
