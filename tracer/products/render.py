"""One render, start to finish: scene folder -> integrator -> image.exr, preview.png, report.json.

Output folder (checked and locked before the first ray; the three files are written after the render
as one set, each read back before it replaces its older version: tracer.products.outputs):

- image.exr: float32 channels R, G, B (apparent luminance, linear Rec.709, Y in cd/m^2), Y, and Y_var
  (variance of each pixel's Y estimate, (cd/m^2)^2); header metadata hud:method, hud:rays, ...
- preview.png: sRGB preview for an eye adapted to the view's log-average luminance (Ward 1994).
- report.json: the figures of :func:`tracer.products.report.build_report`.
"""

from __future__ import annotations

import dataclasses
import json
import time
import uuid
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..analysis.aims import aim_preflight, aim_warnings
from ..analysis.brightness import brightness_theorem, missing_light_warnings
from ..analysis.hud import hud_figures
from ..analysis.optics import check_requirements, optics_block
from ..analysis.sections import find_sections
from ..core.errors import EstimateOverflowError, StoppedBeforeFirstBatch
from ..core.imageio import read_exr_channels, read_image, write_exr
from ..core.units import luminance
from ..methods import INTEGRATORS, Budget, RenderResult
from ..methods.base import MIN_REPLICATES
from ..optics.pupil import pupil_diameter_mm
from ..runtime.parallel import render_parallel
from ..scene import Scene, load_scene
from ..scene.binocular import eye_for
from ..transport.eye import ThinLensEye
from ..transport.world import World
from .optics import clean
from .outputs import OutputFile, OutputSet, png_file, write_as_set
from .report import build_report, finite_json
from .tonemap import adaptation_luminance, tonemap_ward

#: The files of a render, written as a set (tracer.products.outputs).
OUTPUT_NAMES = ("image.exr", "preview.png", "report.json")


def _finite_planes(channels: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The channels as float32 planes; :class:`EstimateOverflowError` if one holds NaN or Inf so."""
    planes = {k: np.asarray(v, dtype=np.float32) for k, v in channels.items()}
    for name, c32 in planes.items():
        if not np.all(np.isfinite(c32)):
            biggest = float(np.nanmax(np.abs(np.asarray(channels[name], dtype=np.float64))))
            raise EstimateOverflowError(f"image.exr: channel {name} does not fit in float32 (largest |value| "
                                        f"{biggest:.3g}): the scene's luminances or fluxes are too large")
    return planes


def report_file(report: dict) -> OutputFile:
    """report.json as a file of a set, checked by reading its run id back."""
    text = finite_json(report)

    def check(path):
        if json.loads(Path(path).read_text())["run_id"] != report["run_id"]:
            raise ValueError("the report read back differs from the one written")

    return OutputFile("report.json", lambda p: Path(p).write_text(text), check)


def output_files(channels: dict[str, np.ndarray], attrs: dict, preview: np.ndarray, report: dict) -> list[OutputFile]:
    """The render's three files, each with its read-back check (the EXR's and the preview's pixels
    compared with those written)."""
    planes = _finite_planes(channels)
    report_out = report_file(report)  # its JSON checked before any file is written

    def check_exr(path):
        got, got_attrs = read_exr_channels(path)
        if set(got) != set(planes) or any(not np.array_equal(got[k], planes[k]) for k in planes):
            raise ValueError("the pixels read back differ from those written")
        if got_attrs.get("hud:run_id") != attrs["hud:run_id"]:
            raise ValueError("the header read back differs from the one written")

    return [OutputFile("image.exr", lambda p: write_exr(p, planes, attrs), check_exr),
            png_file("preview.png", preview), report_out]


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
                  seconds=budget.seconds if budget.since is not None or budget.seconds is None
                  else max(1e-3, budget.seconds - (time.perf_counter() - t0)), since=budget.since)
    found = {"pilot_rays": first.rays, "pilot_seconds": first.seconds, "adaptation_mode": spec.adaptation,
             "pilot_adaptation_luminance_cd_m2": adapt, "pupil_diameter_mm": pupil,
             "first_guess_pupil_diameter_mm": spec.pupil_diameter_mm,
             "formula": "Watson & Yellott 2012, doi:10.1167/12.10.12 (60 deg field, both eyes)"}
    return rebuilt, left, found


def run_render(integrator, budget: Budget, workers: int = 1, progress=None, should_stop=None,
               preview=None, scheduler: str | None = None, keep_pool: bool = True) -> tuple[object, RenderResult]:
    """Run ``integrator`` for ``budget`` on ``workers`` processes (tracer.runtime.parallel) or in this one:
    the command line's render and Blender's, with the two callables of the seam (``progress``,
    ``should_stop``) and the optional ``preview(film)`` (tracer.methods.base.drive); with ``scheduler``
    (a Dask scheduler's address) on that cluster instead; ``keep_pool`` false ends the worker pool with
    the render (no render follows in this process). Where the eye's
    pupil follows the image, a pilot finds it first (:func:`_follow_pupil`). Returns the integrator that
    rendered (rebuilt for that pupil) and the result. Raises
    :class:`~tracer.core.errors.StoppedBeforeFirstBatch` when ``should_stop`` ended the render before its
    first batch (there is no estimate, and a black image would read as a scene without light), and
    FloatingPointError if the estimate holds NaN or Inf (a bug: the estimators never make them)."""
    pupil = None
    if integrator.eye.spec.pupil_from_image:
        integrator, budget, pupil = _follow_pupil(integrator, budget, workers, should_stop)
    if scheduler is not None:  # a Dask cluster (tracer.runtime.distributed): the same batches, the same image
        from ..runtime.distributed import connect, render_dask

        result = render_dask(integrator, budget, connect(scheduler), None, progress, should_stop, preview)
    elif workers > 1:
        result = render_parallel(integrator, budget, workers, progress, should_stop, preview, keep_pool)
    else:
        result = integrator.render(budget, progress, should_stop, preview)
    _check_started(result)
    if pupil is not None:
        result.extra["pupil"] = pupil
    if not result.film.finite():
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


def _nearest(known: np.ndarray) -> np.ndarray:
    """For each position along the last axis of ``known`` (..., n), the index of the nearest known one
    along that axis (the left one on a tie; n where the line has none)."""
    n = known.shape[-1]
    at = np.arange(n, dtype=np.int32)
    left = np.where(known, at, np.int32(-1))
    np.maximum.accumulate(left, axis=-1, out=left)
    right = np.where(known, at, np.int32(n))[..., ::-1]
    np.minimum.accumulate(right, axis=-1, out=right)
    right = right[..., ::-1]
    use_right = (left < 0) | ((right < n) & (at - left > right - at))
    left[use_right] = right[use_right]
    return left


def fill_unsampled(image: np.ndarray, missing: np.ndarray) -> int:
    """Give the pixels ``missing`` (H, W) of ``image`` (H, W, 3), which no sample reached (a render that
    stopped before one sample per pixel), the value of the nearest sampled pixel of their row, or of the
    nearest row that has one (their Y_var stays 0: unmeasured). Returns how many were missing."""
    count = int(missing.sum())
    if count == 0 or count == missing.size:
        return count
    h, w = missing.shape
    known = ~missing
    col = _nearest(known)  # (H, W): in each row, the nearest sampled column (w where the row has none)
    row = _nearest(known.any(axis=1))  # (H,): the nearest row that has a sampled pixel
    flat = image.reshape(-1, image.shape[-1])
    for y in range(h):  # a row at a time: every pixel's source, itself where sampled
        flat[y * w:(y + 1) * w] = flat[row[y] * w + col[row[y]]]
    return count


def render_products(world: World, integrator, result: RenderResult, budget: Budget, analyse: bool = True) -> Products:
    """The image, report and EXR contents of a finished render (see :class:`Products`), with the
    analysis (:func:`add_analysis`) unless ``analyse`` is false. An image made of channels (the hybrid
    method: film groups) also gets each channel as EXR layer ``<channel>.R, .G, .B, .Y, .Y_var``.
    Pixels that no sample reached (a render stopped before one sample per pixel) show their nearest
    sampled neighbour's value (:func:`fill_unsampled`); the report's ``image.samples_per_pixel`` says
    how many."""
    scene = world.scene
    film = result.film
    image = film.rgb()
    var_y = film.variance_y()
    counts = film.sample_counts()
    unsampled = fill_unsampled(image, counts == 0) if counts is not None else 0
    y = luminance(image)
    mode = world.eye.spec.adaptation
    preview, info = tonemap_ward(image, adaptation_luminance(y, mode))
    info["adaptation_mode"] = mode
    channels_y = {g: luminance(film.rgb(g)) for g in film.groups if g}
    report = build_report(scene, result, image, var_y, info, budget, None, integrator.efficiency_definition)
    report["polarisation"] = world.polarisation_report()
    report["hud"] = report["optics"] = None
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
    if counts is not None:
        report["image"]["samples_per_pixel"] = {"mean": float(counts.mean()), "min": int(counts.min()),
                                                "max": int(counts.max()), "unsampled_pixels": unsampled}
    pending = world.accel is not None
    report["analysis"] = "pending" if pending else "not run"  # what add_analysis adds: "done"
    report["analysis_seconds"] = None
    products = Products(image, y, var_y, preview, report, channels, attrs)
    if analyse:
        add_analysis(products, world, integrator, result)
    return products


def add_analysis(products: Products, world: World, integrator, result: RenderResult) -> float:
    """Add to ``products.report`` what the scene's optics say of the image: the brightness-theorem
    comparison, the HUD figures (symbols and background from the sections of
    :mod:`tracer.analysis.sections`) and the optical analysis from the scene's own eye; for a hybrid
    render the HUD figures read the symbols off the HUD channel and the background behind them off the
    environment channel. A stopped render (``result.partial``) gets its HUD figures only, marked
    ``"partial": true`` (the figures of what it accumulated; the rest would delay the stop); a scene
    without geometry none. Returns the seconds it took."""
    t0 = time.perf_counter()
    if world.accel is None:
        return 0.0
    scene, film, report = world.scene, result.film, products.report
    sections = find_sections(world)
    sections_seconds = time.perf_counter() - t0
    channels_y = {g: products.channels[f"{g}.Y"] for g in film.groups if g}
    report["hud"] = hud_figures(world, channels_y["hud"], channels_y.get("environment"), sections) \
        if "hud" in channels_y else hud_figures(world, products.y, sections=sections)
    if result.partial:
        if report["hud"] is not None:
            report["hud"]["partial"] = True
        seconds = time.perf_counter() - t0
        report["analysis"], report["analysis_seconds"] = "hud figures only (stopped render)", seconds
        return seconds
    t1 = time.perf_counter()
    analysis = brightness_theorem(world, products.y, products.var_y, integrator.renders_environment, sections)
    analysis["seconds"] = sections_seconds + time.perf_counter() - t1  # the sections are its too
    counts = film.sample_counts()
    unmeasured = 0 if counts is None else int((counts < MIN_REPLICATES).sum())
    if unmeasured:  # a render stopped before two samples per pixel: no error bars to judge a difference by
        analysis["not_comparable"].append(f"{unmeasured:,} pixels hold fewer than {MIN_REPLICATES} samples, so "
                                          "the rendered means have no error bars to compare by")
    report["brightness_theorem"] = analysis
    report["warnings"] += [f"brightness theorem not compared: {r}" for r in analysis["not_comparable"]]
    if not unmeasured:
        report["warnings"] += missing_light_warnings(analysis, result.method)
    if result.method in ("forward", "photon"):
        report["warnings"] += aim_warnings(analysis)
    # the optical analysis from the scene's own eye (the design eye point), whichever eye rendered
    own_eye = world.eye.spec is scene.eye
    report["optics"] = clean(optics_block(scene, world if own_eye else None))
    report["warnings"] += [f"optics: {w}" for w in report["optics"].get("warnings", [])]
    if "error" in report["optics"] and "target" in scene.raw:  # asked for, and not possible
        report["warnings"].append(f"optics: {report['optics']['error']}")
    seconds = time.perf_counter() - t0
    report["analysis"], report["analysis_seconds"] = "done", seconds
    return seconds


def render_scene(scene: Scene, method: str, budget: Budget, seed: int, out_dir: str | Path,
                 progress=None, should_stop=None, batch_size: int | None = None, analyse: bool = True,
                 workers: int = 1, notice=None, eye: str = "centre", scheduler: str | None = None,
                 keep_pool: bool = True):
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
    :class:`~tracer.core.errors.StoppedBeforeFirstBatch` (the folder keeps its earlier outputs). ``eye``:
    "left" or "right" renders what that eye of a binocular pair sees (tracer.scene.binocular; the
    report's image block says which). ``scheduler``: a Dask scheduler's address, to render on that
    cluster (tracer.runtime.distributed) instead of ``workers`` local processes; ``keep_pool``
    (tracer.runtime.parallel.render_parallel) false when no render follows."""
    if method not in INTEGRATORS:
        raise ValueError(f"unknown method {method!r} (known: {', '.join(INTEGRATORS)})")
    if analyse:
        check_requirements(scene)  # the target's requirements, judged after the render: refused before it
    outputs = OutputSet(out_dir, OUTPUT_NAMES, scene_root=scene.root).open()
    try:
        world = World(scene, None if eye == "centre" else ThinLensEye(eye_for(scene, eye)))
        integrator = INTEGRATORS[method](world, seed, batch_size)
        if notice is not None:
            for w in aim_preflight(world, method, integrator.renders_environment):
                notice(f"before the first ray: {w}")
            integrator.notice = notice
        integrator, result = run_render(integrator, budget, workers, progress, should_stop, scheduler=scheduler,
                                        keep_pool=keep_pool)
        pending = analyse and integrator.world.accel is not None
        products = render_products(integrator.world, integrator, result, budget, analyse=False)
        if not pending:
            products.report["analysis"] = "not run"
        if eye != "centre":
            products.report["image"]["eye"] = {"side": eye, "position_mm": integrator.world.eye.position.tolist(),
                                               "ipd_mm": float(scene.target.get("ipd_mm", 65.0))}
        outputs.commit(products.files())
        outputs.keep()
    finally:
        outputs.close()
    if pending and not result.partial and should_stop is not None and should_stop():
        pending = False  # stopped as the image was written: report.json keeps "analysis": "pending"
    if pending:  # after the image is written: its figures follow in report.json, rewritten whole
        if progress is not None:
            progress(1.0, f"image written to {out_dir}; the analysis follows (report.json: HUD figures, brightness "
                   "theorem, optics)")
        add_analysis(products, integrator.world, integrator, result)
        f = report_file(products.report)
        write_as_set(Path(out_dir) / f.name, f.write, f.check)
    return products.report, result


def side_by_side(left: Path, right: Path, out: Path) -> None:
    """The two eyes' previews side by side (left eye on the left, a 4-pixel black gap) as one PNG,
    written as a set of one (tracer.products.outputs.write_as_set)."""
    a, b = (np.rint(read_image(p, linear=True) * 255.0).astype(np.uint8) for p in (left, right))
    gap = np.zeros((a.shape[0], 4, 3), np.uint8)
    rgb = np.concatenate([a[..., :3], gap, b[..., :3]], axis=1)
    f = png_file(out.name, rgb)
    write_as_set(out, f.write, f.check)


def render_folder(scene_dir, method, budget, seed, out_dir, **kw):
    """Load a scene folder and render it (see :func:`render_scene`)."""
    return render_scene(load_scene(scene_dir), method, budget, seed, out_dir, **kw)
