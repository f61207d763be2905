"""What a sweep reads off each run's report: its figures (every number of the report's HUD figures,
luminance, noise and cost: sweep.csv's columns) and its requirements, ``"KEY OP VALUE"`` with KEY a
dotted path into the report (``hud.contrast_ratio``), OP one of ``>= <= > <``, VALUE a number. A KEY
that no report can hold (:data:`REPORT_KEYS`) is refused before the first ray; a run whose report
lacks KEY (a part the scene or the method does not give), or holds no number there, fails the
requirement, and sweep.json says why.
"""

from __future__ import annotations

import dataclasses
import difflib
from dataclasses import dataclass

from ..analysis.hud import HUD_KEYS, SPOT_KEYS
from ..analysis.optics import DESIGN_EXTRAS, DESIGN_KEYS, EYEBOX_KEYS, OpticsError, check_metric
from ..core.jsonpath import Requirement, path_text
from ..core.jsonpath import parse_requirement as parse_text
from ..methods import INTEGRATORS
from ..methods.photon import STORE_KEYS
from ..methods.pilots import STRATA, Pilot
from ..products.report import REPORT_SECTIONS
from ..products.tonemap import ward_info
from ..transport.path import Timers
from .fields import SweepArgumentError

#: The parts of a report whose numeric leaves are a run's figures (sweep.csv's columns), in order.
FIGURES = ("hud", "optics", "luminance", "adaptation_luminance", "noise", "rays", "seconds", "efficiency")


def numeric_leaves(value, prefix: str) -> dict[str, int | float]:
    """Every number in ``value`` (nested blocks and lists) by its dotted key path; booleans, strings
    and nulls are left out."""
    out: dict[str, int | float] = {}
    if isinstance(value, bool) or value is None:
        return out
    if isinstance(value, (int, float)):
        out[prefix] = value
    elif isinstance(value, dict):
        for k, v in value.items():
            out |= numeric_leaves(v, f"{prefix}.{k}" if prefix else k)
    elif isinstance(value, list):
        for i, v in enumerate(value):
            out |= numeric_leaves(v, f"{prefix}[{i}]")
    return out


def run_figures(report: dict) -> dict[str, int | float]:
    """A run's figures (the columns of sweep.csv): every numeric leaf of the report's :data:`FIGURES`."""
    out: dict[str, int | float] = {}
    for key in FIGURES:
        out |= numeric_leaves(report.get(key), key)
    return out


# -- the keys a report can hold -----------------------------------------------------------------------
@dataclass(frozen=True)
class Named:
    """A block of :data:`REPORT_KEYS` whose keys are names the scene gives (an object's, a chain's):
    any name, each holding ``entry``."""

    entry: object


def _block(*keys: str, **blocks) -> dict:
    """A block of :data:`REPORT_KEYS`: ``keys`` hold values (a number, a string, a flag, null),
    ``blocks`` the nested blocks and lists."""
    return dict.fromkeys(keys) | blocks


#: Entries of a list of values (a list holds one node: what each of its elements is).
_VALUES = [None]
#: A section of the brightness-theorem check (tracer.analysis.brightness.brightness_theorem's ``symbol``,
#: ``background`` and ``image``).
_BT_SECTION = _block("pixels", "section_pixels", "rendered_cd_m2", "standard_error_cd_m2", "predicted_cd_m2",
                     "predicted_standard_error_cd_m2", "predicted_photon_standard_error_cd_m2",
                     "predicted_chief_ray_cd_m2", "pupil_fill", "through_specular_cd_m2", "valid",
                     "rendered_over_predicted", "rendered_minus_predicted_sigma",
                     predicted_by_path_cd_m2=Named(None))
#: A pilot of the hybrid and auto methods (tracer.methods.pilots.Pilot.summary: its fields but the images).
_PILOT = _block(*(f.name for f in dataclasses.fields(Pilot) if f.name not in ("image", "variance")), "note",
                relative_variance_medians=_block(*STRATA))
#: A channel of the hybrid and auto methods (tracer.methods.hybrid._Channels.finish).
_CHANNEL = _block("method", "asked", "chosen_by", "skipped", "note", "rays", "paths", "found", "seconds",
                  "batch_size", "every", "efficiency", "mean_cd_m2", "mean_standard_error_cd_m2",
                  sources=_VALUES, pilots=[_PILOT], warnings=_VALUES)

#: Every key a render's report.json can hold, for any scene and method: a block is a dict of its keys
#: (None: a value; a list of one node: a list of such elements; :class:`Named`: keys the scene names).
#: A sweep's ``--require`` and ``--y`` keys are checked against it before the first ray
#: (:func:`check_report_key`), so a mistyped key is refused there rather than found missing in every run.
#: Its top level is tracer.products.report.REPORT_SECTIONS; below it, it follows the code that writes each
#: block, with the lists of keys that code keeps where it keeps one: build_report (run, budget, image
#: figures) and tracer.products.render's render_products, render_scene and add_analysis (``image``'s
#: ``samples_per_pixel`` and ``eye``, the analysis); ``components`` by the methods' film components
#: (``components`` of every class in tracer.methods.INTEGRATORS), ``stage_seconds`` by
#: tracer.transport.path.Timers.STAGES, ``preview`` by tracer.products.tonemap.ward_info;
#: ``method_details`` by every method's ``finish`` (tracer/methods/: base, backward, forward, photon
#: with its STORE_KEYS, hybrid and auto with tracer.methods.pilots.Pilot), the worker pools
#: (tracer.runtime.parallel, distributed) and the pupil's pilot (tracer.products.render._follow_pupil);
#: ``brightness_theorem`` by tracer.analysis.brightness.brightness_theorem (its sections, the ghost, the
#: photon map's summary: tracer.methods.photon.PhotonMap.summary; the aims' coverage:
#: tracer.transport.chains.aim_coverage); ``polarisation`` by tracer.transport.world.World.polarisation_report;
#: ``hud`` by tracer.analysis.hud.HUD_KEYS and SPOT_KEYS (and ``partial``, a stopped render's mark);
#: ``optics`` by tracer.analysis.optics.report_block (its DESIGN_KEYS, DESIGN_EXTRAS and EYEBOX_KEYS).
#: Which of them a report holds depends on the scene and the method (a ghost only where a second chain
#: crosses the LCD, ``channels`` only for hybrid and auto): a run whose report lacks the key fails the
#: requirement. tests/scans/test_requirements.py checks that every number of the reports of every
#: method has its key here.
REPORT_KEYS: dict = _block(
    "run_id", "tracer", "method", "seed", "partial", "rays", "paths", "paths_found_light", "batches", "workers",
    "seconds", "rays_per_second", "efficiency", "efficiency_definition", "replicates", "adaptation_luminance",
    "adaptation_mode", "analysis", "analysis_seconds",
    scene=_block("name", "folder", "hash"),
    budget=_block("rays", "seconds"),
    luminance=_block("unit", "mean", "max", "log_average", "mean_standard_error", "mean_standard_error_from"),
    components={name: _block("normalised_by", "count", "mean_cd_m2", "standard_error_cd_m2", "share")
                for cls in INTEGRATORS.values() for name in cls.components},
    stage_seconds=_block(*Timers.STAGES),
    noise=_block("median_relative_standard_error_lit_pixels", "from"),
    preview=_block(*ward_info(1.0, 100.0, 0.0), "adaptation_mode"),
    image=_block("width", "height", channels=_VALUES, pixel_mrad=_VALUES,
                 samples_per_pixel=_block("mean", "min", "max", "unsampled_pixels"),
                 eye=_block("side", "ipd_mm", position_mm=_VALUES)),
    warnings=_VALUES,
    method_details=_block(
        "setup_seconds", "steady_rays_per_second", "workers", "startup_seconds", "pool", "dask_workers", "scheduler",
        "samples_per_pixel", "next_event", "connection_share", "emitted_flux_lm",
        *STORE_KEYS,  # auto's channel rendered by photon keeps the photon figures of its batches
        roulette=_block("reference_luminance_cd_m2", "threshold_cd_m2", "pilot_rays"),
        max_depth_cut=_block("paths", "probe_segments", "still_going_after_probe", "missing_luminance_cd_m2",
                             "missing_share_of_mean", "missing_is_lower_bound", "image_mean_standard_error_cd_m2"),
        pupil=_block("pilot_rays", "pilot_seconds", "adaptation_mode", "pilot_adaptation_luminance_cd_m2",
                     "pupil_diameter_mm", "first_guess_pupil_diameter_mm", "formula"),
        samples_per_pixel_range=_VALUES,
        exit_pupil=_block("radius_mm", "share", "area_inside_pupil_mm2", "area_rest_mm2", "paper_w",
                          center_mm=_VALUES),
        photon=_block("replicates_per_batch", "initial_radius_mm", "initial_radius_from", "alpha", "final_radius_mm",
                      "photons_emitted", "photons_stored", "photon_paths_cut_at_max_depth",
                      "eye_paths_cut_at_max_depth", "visibility_points", "photons_per_visibility_point"),
        component_shares=_block(*INTEGRATORS["photon"].components),
        channels=_block(hud=_CHANNEL, environment=_CHANNEL, scene=_CHANNEL)),
    brightness_theorem=_block(
        "method", "assumptions", "grid_stride_px", "valid", "image_path", "seconds",
        not_comparable=_VALUES, notes=_VALUES,
        paths=[_block("path", "pixels_fraction", "predicted_mean_cd_m2", "transfer_factor_mean")],
        photon_map=_block("photons_emitted", "photons_stored", "radius_mm", "target_photons_per_gather",
                          "photon_paths_cut_at_max_depth", "seed"),
        symbol=_BT_SECTION, background=_BT_SECTION, image=_BT_SECTION,
        aim_coverage=Named(_block("target", "coverage")),
        ghost=_block("path", "predicted_cd_m2", "ratio_to_symbol", "offset_mrad", offset_px=_VALUES)),
    polarisation=_block("mode", "stokes_vectors", polarising_elements=_VALUES),
    hud=_block(*(k for k in HUD_KEYS if k != "spot"), "partial",
               spot=_block(*(k for k in SPOT_KEYS if k != "peak_pixel"), peak_pixel=_VALUES)),
    optics=_block(
        "requirements_met", "seconds", "error",
        chains=_block("pgu", "primary", "ghost"),
        target=_block("distance_mm", "look_down_deg", "look_over_deg", "ipd_mm", fov_deg=_VALUES, eyebox_mm=_VALUES,
                      field_grid=_VALUES, eye_grid=_VALUES),
        design_eye=_block(*DESIGN_KEYS, *DESIGN_EXTRAS, "field_points_seen"),
        eyebox=_block(*EYEBOX_KEYS, "eye_points_seeing_every_field_point"),
        requirements=[_block("requirement", "value", "met", "why")],
        warnings=_VALUES))


def _nearest(name: str, known) -> str | None:
    """The key of ``known`` a user most likely meant by ``name``: the closest spelling, else one that
    ``name`` begins or is a word of (``ratio`` for ``ratio_to_symbol``)."""
    near = difflib.get_close_matches(name, known, n=1)
    if near:
        return near[0]
    longer = [k for k in known if k.startswith(name) or name in k.split("_")]
    return longer[0] if longer else None


def _check_below(argument: str, steps) -> None:
    """Refuse a report key (its steps, :func:`tracer.core.jsonpath.parse_field`) that leaves
    :data:`REPORT_KEYS` or ends where a report holds a block or a list, never a number: a mistyped
    name is answered with the nearest one. Raises :class:`SweepArgumentError`."""
    node, done = REPORT_KEYS, ()
    for kind, arg in steps:
        here = path_text(done)
        if kind == "index":
            if not isinstance(node, list):
                raise SweepArgumentError(argument, f"{here} is not a list: it has no element [{arg}]")
            node = node[0]
        elif isinstance(node, Named):
            node = node.entry
        elif isinstance(node, dict):
            if arg not in node:
                near = _nearest(arg, list(node))
                hint = f" (did you mean {near!r}?)" if near else ""
                raise SweepArgumentError(argument, f"a run's report has no {here}.{arg}{hint}; {here} holds: "
                                                   f"{', '.join(node)}")
            node = node[arg]
        elif isinstance(node, list):
            raise SweepArgumentError(argument, f"{here} is a list: give an element's index ({here}[0])")
        else:
            raise SweepArgumentError(argument, f"{here} is a value, not a block: it has no field {arg!r}")
        done = (*done, arg)
    here = path_text(done)
    if isinstance(node, dict):
        raise SweepArgumentError(argument, f"{here} is a block of figures, not a number: name one of them "
                                           f"({', '.join(f'{here}.{k}' for k in list(node)[:3])}, ...)")
    if isinstance(node, Named):
        raise SweepArgumentError(argument, f"{here} is a block of figures by name, not a number")
    if isinstance(node, list):
        raise SweepArgumentError(argument, f"{here} is a list, not a number: give an element's index ({here}[0])")


# -- requirements -------------------------------------------------------------------------------------
def check_report_key(argument: str, steps, optics_only: bool = False) -> None:
    """A report key's first name must be a section of every report (tracer.products.report.REPORT_SECTIONS),
    and the rest a path that some report holds (:data:`REPORT_KEYS`, a number at its end), so that a
    mistyped key is refused before the runs rather than found missing in each; below ``optics``,
    ``design_eye`` and ``eyebox`` must name a metric of the optical analysis
    (tracer.analysis.optics.REQUIREMENT_KEYS). ``optics_only`` (a sweep of the optical analysis alone):
    the key must lie in ``optics``. (Which keys a report holds depends on the scene and the method: a
    run whose report lacks one fails the requirement.) Raises :class:`SweepArgumentError`."""
    name = steps[0][1]
    if optics_only and name != "optics":
        raise SweepArgumentError(argument, "a sweep of the optical analysis (--optics) reads optics.* only "
                                           "(optics.design_eye.ghost_separation_arcmin)")
    if name not in REPORT_SECTIONS:
        near = difflib.get_close_matches(name, REPORT_SECTIONS, n=1)
        hint = f"did you mean {near[0]!r}? " if near else ""
        raise SweepArgumentError(argument, f"{name!r} is not a section of a run's report.json ({hint}the sections "
                                           f"are: {', '.join(REPORT_SECTIONS)})")
    names = [arg for _, arg in steps[1:]]
    if name == "optics" and names and names[0] in ("design_eye", "eyebox"):
        try:
            check_metric(names, name)
        except OpticsError as e:
            raise SweepArgumentError(argument, str(e)) from None
    _check_below(argument, steps)


def parse_requirement(text: str, optics_only: bool = False) -> Requirement:
    """``"KEY OP VALUE"`` (spaces optional) as a :class:`Requirement` on a run's report
    (:func:`check_report_key`). Raises :class:`SweepArgumentError`."""
    argument = f"--require {text}"
    try:
        req = parse_text(text)
    except ValueError as e:
        raise SweepArgumentError(argument, str(e).replace("(hud.contrast_ratio)", "into the report "
                                                          "(hud.contrast_ratio)")) from None
    check_report_key(argument, req.steps, optics_only)
    return req
