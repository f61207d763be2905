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
import functools
import json
import time
import uuid
from pathlib import Path

import numpy as np

from ..analysis.aims import aim_preflight, aim_warnings
from ..analysis.brightness import analysis_photon_map, brightness_theorem, missing_light_warnings
from ..analysis.hud import hud_figures
from ..analysis.optics import check_requirements, optics_block
from ..analysis.sections import find_sections
from ..core.errors import EstimateOverflowError, StoppedBeforeFirstBatch
from ..core.imageio import read_exr_rows, read_image, write_exr_pixels
from ..core.units import luminance, luminance3
from ..methods import INTEGRATORS, Budget, RenderResult
from ..methods.base import MIN_REPLICATES
from ..optics.pupil import pupil_diameter_mm
from ..runtime.parallel import render_parallel
from ..scene import Scene, load_scene
from ..scene.binocular import eye_for
from ..transport.chains import specular_paths
from ..transport.eye import ThinLensEye
from ..transport.world import World
from .fill import ImageFill
from .optics import clean
from .outputs import OutputFile, OutputSet, png_file, write_as_set
from .report import build_report, finite_json
from .tonemap import (
    DISPLAY_MAX_LUMINANCE,
    adaptation_luminance,
    check_preview_input,
    log_average_luminance,
    ward_codes,
    ward_info,
)

#: The files of a render, written as a set (tracer.products.outputs).
OUTPUT_NAMES = ("image.exr", "preview.png", "report.json")


def _float32(values: np.ndarray, channels: list[str]) -> np.ndarray:
    """``values`` (n,) or (n, len(channels)) as float32; :class:`EstimateOverflowError` naming the
    first EXR channel (a column) that does not fit."""
    out = values.astype(np.float32)
    bad = ~np.isfinite(out.reshape(len(out), len(channels)))
    if bad.any():
        k = int(np.argmax(bad.any(axis=0)))
        biggest = float(np.abs(values.reshape(len(out), len(channels))[:, k]).max())
        raise EstimateOverflowError(f"image.exr: channel {channels[k]} does not fit in float32 (largest |value| "
                                    f"{biggest:.3g}): the scene's luminances or fluxes are too large")
    return out


def report_file(report: dict) -> OutputFile:
    """report.json as a file of a set, checked by reading its run id back."""
    text = finite_json(report)

    def check(path):
        if json.loads(Path(path).read_text())["run_id"] != report["run_id"]:
            raise ValueError("the report read back differs from the one written")

    return OutputFile("report.json", lambda p: Path(p).write_text(text), check)


#: Rows read back at each end of image.exr to check it (OpenEXR's ZIP blocks hold 16 rows).
CHECKED_ROWS = 16


def exr_file(names: list[str], pixels: np.ndarray, attrs: dict) -> OutputFile:
    """image.exr (channels ``names`` of the interleaved float32 ``pixels`` (H, W, C), header
    ``attrs``) as a file of a set, checked by reading back its header (the run id) and its first and
    last :data:`CHECKED_ROWS` rows, compared with those meant. A read-back right after writing comes
    from the system's cache, not the disk: what it can find is a file the writer left short (a full
    disk, which OpenEXR does not always report) or unreadable, and the last rows find that; decoding
    the whole of a 4K image again would take longer than writing it."""
    h = pixels.shape[0]

    def check(path):
        for a, b in ((0, min(h, CHECKED_ROWS)), (max(0, h - CHECKED_ROWS), h)):
            got, got_attrs = read_exr_rows(path, a, b)
            if set(got) != set(names) or any(not np.array_equal(got[k], pixels[a:b, :, i])
                                             for i, k in enumerate(names)):
                raise ValueError(f"the pixels of rows {a} to {b} read back differ from those written")
        if got_attrs.get("hud:run_id") != attrs["hud:run_id"]:
            raise ValueError("the header read back differs from the one written")

    return OutputFile("image.exr", lambda p: write_exr_pixels(p, names, pixels, attrs), check)


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


class Products:
    """What a render gives its user, the same from the command line and from Blender: the image
    (H, W, 3) float32 cd/m^2 linear Rec.709, its luminance ``y`` and that luminance's variance
    ``var_y`` (H, W) float64 (made when first asked for: the analysis and Blender ask, the files do
    not), the preview (sRGB uint8, Ward 1994), the report (:func:`build_report`, with ``run_id``), the
    EXR's channels ``names`` interleaved in ``pixels`` (H, W, C) float32 (``channels``: each by name,
    a view) and its header attributes (``hud:*``)."""

    def __init__(self, fill: ImageFill, names: list[str], pixels: np.ndarray, preview: np.ndarray, report: dict,
                 attrs: dict, layout_y: np.ndarray, layout_var_y: np.ndarray, group_layout_y: dict[str, np.ndarray]):
        self.fill, self.names, self.pixels, self.preview, self.report = fill, names, pixels, preview, report
        self.attrs = attrs
        # the image's luminance (cd/m^2) and its variance per position of the film's layout, and each
        # channel's luminance (a film group's)
        self._layout_y, self._layout_var_y = layout_y, layout_var_y
        self._group_layout_y = group_layout_y
        self.image = pixels[..., :3]
        self.channels = {name: pixels[..., k] for k, name in enumerate(names)}  # views, (H, W) each

    @functools.cached_property
    def y(self) -> np.ndarray:
        return self.fill.image(self._layout_y)

    @functools.cached_property
    def var_y(self) -> np.ndarray:
        return self.fill.as_film(self._layout_var_y)

    def group_y(self, group: str) -> np.ndarray:
        """(H, W) float64 luminance, cd/m^2, of one channel of the image (a film group)."""
        return self.fill.image(self._group_layout_y[group])


def _median_relative_error(y: np.ndarray, var_y: np.ndarray, fill: ImageFill) -> float | None:
    """The median relative standard error of the lit pixels that hold the two samples an error needs,
    from per-position luminance ``y`` and variance ``var_y`` (layout,) of ``fill``'s film (a filled
    pixel is unmeasured); None where no pixel is lit and measured."""
    lit = y > 1e-6 * max(float(y.max(initial=0.0)), 1e-300)
    if fill.per_position is not None:
        lit &= fill.per_position >= MIN_REPLICATES
    elif fill.film.fewest_replicates < MIN_REPLICATES:
        return None
    return float(np.median(np.sqrt(var_y[lit]) / y[lit])) if lit.any() else None


def render_products(world: World, integrator, result: RenderResult, budget: Budget, analyse: bool = True,
                    stage=None) -> Products:
    """The image, report and EXR contents of a finished render (see :class:`Products`), with the
    analysis (:func:`add_analysis`) unless ``analyse`` is false. An image made of channels (the hybrid
    method: film groups) also gets each channel as EXR layer ``<channel>.R, .G, .B, .Y, .Y_var``.
    Pixels that no sample reached (a render stopped before one sample per pixel) show their nearest
    sampled neighbour's value (tracer.products.fill); the report's ``image.samples_per_pixel`` says
    how many. Every per-pixel figure is computed once per position of the film's layout (the pixels
    sampled, while few are: tracer.core.film) and then spread over the image, so that a large retina
    stopped early costs by its samples; the numbers are those of computing them pixel by pixel.
    ``stage(file)``, where given, takes image.exr and preview.png as soon as each is ready
    (tracer.products.outputs.Staging: written while the rest is computed)."""
    scene, film = world.scene, result.film
    fill = ImageFill(film)
    run_id = uuid.uuid4().hex
    groups = [g for g in film.groups if g]
    attrs = {"hud:method": result.method, "hud:rays": str(result.rays), "hud:paths": str(result.paths),
             "hud:seconds": float(result.seconds), "hud:efficiency": float(result.efficiency),
             "hud:seed": str(result.seed), "hud:scene_hash": scene.scene_hash, "hud:partial": int(result.partial),
             "hud:run_id": run_id,
             "hud:units": "R,G,B,Y: apparent luminance cd/m^2 (Rec.709, Y=0.2126R+0.7152G+0.0722B); "
                          "Y_var: (cd/m^2)^2" + ("; <channel>.R,G,B,Y,Y_var: the same for each channel"
                                                 if groups else "")}
    rgb = film.layout_rgb()  # (3, layout) cd/m^2
    check_preview_input(rgb)
    y_at, var_at = luminance3(rgb), film.layout_variance_y()
    # the EXR's channels as one table of float32 columns (layout, C), the image's then each channel's
    # layer, spread over the pixels in one pass; Y_var is then put at the sampled pixels only (0 where
    # unmeasured: a filled pixel borrows its neighbour's value, not its error)
    names, columns, variances, group_y = [], [], [], {}
    for g in [None, *groups]:
        rgb_g = rgb if g is None else film.layout_rgb(g)
        prefix = "" if g is None else f"{g}."
        names += [prefix + c for c in ("R", "G", "B", "Y", "Y_var")]
        if g is not None:
            group_y[g] = luminance3(rgb_g)
        columns += [*rgb_g, y_at if g is None else group_y[g], np.zeros(len(y_at))]
        variances.append(var_at if g is None else film.layout_variance_y(g))
    pixels = fill.image(_float32(np.stack(columns, axis=1), names))  # (H, W, C)
    for i, var_g in enumerate(variances):
        fill.place(pixels, 5 * i + 4, _float32(var_g, [names[5 * i + 4]]))
    if stage is not None:
        stage(exr_file(names, pixels, attrs))
    values, weights = fill.population(y_at)  # the image's luminance statistics, from its distinct values
    mode = world.eye.spec.adaptation
    adapt = adaptation_luminance(values, mode, weights)
    codes, clipped = ward_codes(rgb.T, adapt)  # (layout, 3) sRGB codes: one per position, then spread
    preview = fill.image(codes)  # (H, W, 3)
    if stage is not None:
        stage(png_file("preview.png", preview))
    is_clipped, shown = fill.population(clipped.astype(np.float64))
    info = ward_info(adapt, DISPLAY_MAX_LUMINANCE, float(np.average(is_clipped, weights=shown)))
    info["adaptation_mode"] = mode
    figures = {"mean": float(np.average(values, weights=weights)), "max": float(values[weights > 0].max()),
               "log_average": log_average_luminance(values, weights=weights),
               "median_relative_error": _median_relative_error(y_at, var_at, fill)}
    report = build_report(scene, result, figures, fill.shape, info, budget, integrator.efficiency_definition)
    report["polarisation"] = world.polarisation_report()
    report["hud"] = report["optics"] = None
    report = {"run_id": run_id} | report
    report["image"]["channels"] = names
    if fill.counts is not None:
        mean, fewest, most = fill.counts
        report["image"]["samples_per_pixel"] = {"mean": mean, "min": fewest, "max": most,
                                                "unsampled_pixels": fill.unsampled}
    pending = world.accel is not None
    report["analysis"] = "pending" if pending else "not run"  # what add_analysis adds: "done"
    report["analysis_seconds"] = None
    products = Products(fill, names, pixels, preview, report, attrs, y_at, var_at, group_y)
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
    # A screen lit through optics gets a photon map (not for a stopped render: it would delay the stop),
    # which tells its symbols (the LCD's photons) and joins the brightness-theorem prediction.
    chains = specular_paths(world, environment=False)
    pmap = None if result.partial else analysis_photon_map(world, chains, integrator.seed)
    sections = find_sections(world, chains, photons=pmap)
    sections_seconds = time.perf_counter() - t0
    channels_y = {g: products.group_y(g) for g in film.groups if g}
    report["hud"] = hud_figures(world, channels_y["hud"], channels_y.get("environment"), sections) \
        if "hud" in channels_y else hud_figures(world, products.y, sections=sections)
    if result.partial:
        if report["hud"] is not None:
            report["hud"]["partial"] = True
        seconds = time.perf_counter() - t0
        report["analysis"], report["analysis_seconds"] = "hud figures only (stopped render)", seconds
        return seconds
    t1 = time.perf_counter()
    analysis = brightness_theorem(world, products.y, products.var_y, integrator.renders_environment, sections,
                                  seed=integrator.seed, photon_map=pmap)
    analysis["seconds"] = sections_seconds + time.perf_counter() - t1  # the sections are its too
    counts = film.sample_counts()
    unmeasured = 0 if counts is None else int((counts < MIN_REPLICATES).sum())
    if unmeasured:  # a render stopped before two samples per pixel: no error bars to judge a difference by
        analysis["not_comparable"].append(f"{unmeasured:,} pixels hold fewer than {MIN_REPLICATES} samples, so "
                                          "the rendered means have no error bars to compare by")
    report["brightness_theorem"] = analysis
    report["warnings"] += [f"brightness theorem not compared: {r}" for r in analysis["not_comparable"]]
    if not unmeasured:  # by the methods that rendered it (auto's and hybrid's channels name theirs)
        used = {c["method"] for c in (result.extra.get("channels") or {}).values() if c.get("method")}
        report["warnings"] += missing_light_warnings(analysis, used or result.method)
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
        with outputs.staging() as stage:  # the image and preview written as soon as each is made
            products = render_products(integrator.world, integrator, result, budget, analyse=False, stage=stage.add)
            if not pending:
                products.report["analysis"] = "not run"
            if eye != "centre":
                products.report["image"]["eye"] = {"side": eye,
                                                   "position_mm": integrator.world.eye.position.tolist(),
                                                   "ipd_mm": float(scene.target.get("ipd_mm", 65.0))}
            stage.add(report_file(products.report))
            stage.finish()
        outputs.keep()
    finally:
        outputs.close()
    if pending and not result.partial and should_stop is not None and should_stop():
        pending = False  # stopped as the image was written: report.json keeps "analysis": "pending"
    if pending:  # after the image is written: its figures follow in report.json, rewritten whole
        if progress is not None:
            progress(1.0, f"image written to {out_dir}; " + (
                "its HUD figures follow into report.json (a stopped render: marked partial, no brightness theorem or "
                "optics)" if result.partial else
                "the analysis follows (report.json: HUD figures, brightness theorem, optics)"))
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
