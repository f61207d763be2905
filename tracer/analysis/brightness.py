"""The brightness-theorem comparison: the render against the deterministic prediction of the specular
chains (:mod:`tracer.transport.chains`) on the image's sections (paper sec. 4.1's symbols and
background: the pixels whose chief ray's dominant chain crosses a clear or a black LCD cell), with the
ghost image's ratio and offset, and the warnings of light a render missed.

The brightness theorem: luminance is conserved along a lossless specular chain, so the luminance the
eye sees through mirrors, glass and an LCD is the product of their reflectances and transmittances
times the luminance behind them (../shared/reference/hud-physics.md, "Photometry").
"""

from __future__ import annotations

import math

import numpy as np

from ..core.kept import KeptResults
from ..core.units import luminance
from ..methods.photon import PhotonMap
from ..transport.chains import ENV_SAMPLES, QUAD_TRUST, aim_coverage, specular_paths
from ..transport.world import World
from .sections import Sections, find_sections

#: Particles of the photon map that follows the light reaching scattering surfaces through specular optics
#: (a projection lens, a condenser) where the chief rays find such a surface: about 7 % per gather
#: (tracer.methods.photon.PhotonMap) and 1.5 s on hud-screen (2 cores).
ANALYSIS_PHOTONS = 250_000
#: The random streams of the analysis' photon maps (with the render's seed): none a render's batch uses
#: (batch k draws from stream k), so that the prediction does not share photons with a photon render.
ANALYSIS_STREAM, ANALYSIS_PILOT_STREAM = 2**31 - 2, 2**31 - 3
#: Particles of the pilot photon map that tells whether scattering surfaces in view are lit through other
#: surfaces where the quadrature names no specular blocker (:func:`lit_through_optics`).
PILOT_PHOTONS = 50_000
#: Pixels (evenly spaced over the chief rays' grid) whose chains are listed under "paths" where a photon map
#: is built: a gather at every grid point took 13 s on hud-screen (the breakdown of the sections' own
#: prediction is in each section).
LISTED_PIXELS = 300


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
#: The same where a photon map adds light to scattering surfaces: every ray gathers photons (a few hundred
#: each), and a diffuse screen fills the pupil, so 9 rays per pixel do (36 took 6 of the 9 s of
#: hud-screen's analysis).
PUPIL_GRID_WITH_PHOTONS = 3


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


#: Paths named in a section's breakdown; the rest are summed as "other paths".
BREAKDOWN_PATHS = 3


def per_pixel(paths: list[dict], n: int) -> tuple[np.ndarray, list[np.ndarray], np.ndarray, np.ndarray]:
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


def evenly(idx: np.ndarray, k: int) -> np.ndarray:
    """At most ``k`` entries of ``idx`` evenly spaced through it."""
    if len(idx) <= k:
        return idx
    return idx[np.unique(np.linspace(0, len(idx) - 1, k).round().astype(np.int64))]


def missing_light_warnings(analysis: dict, method: str | set[str]) -> list[str]:
    """A warning for each comparable section of :func:`brightness_theorem` that the render puts more than
    MISSING_SHARE and MISSING_SIGMA combined standard errors below the prediction: light along specular
    chains that the render did not find, and that its error bars cannot show (a standard error from the
    replicates sees only the paths that were sampled). In forward tracing that is light reached through
    directions its aim leaves to the unaimed share: glass or a lens between an emitter and its aim
    target bends the aimed rays away from the target, so the light that does reach the eye arrives in
    rare heavy particles. ``method``: the method that rendered the image, or those of its channels (auto,
    hybrid), which the advice depends on."""
    methods = {method} if isinstance(method, str) else set(method)
    out = []
    for key in ("symbol", "background", "image"):
        entry = analysis.get(key)
        if not entry or entry.get("rendered_minus_predicted_sigma") is None:
            continue
        ratio, sigma = entry["rendered_over_predicted"], entry["rendered_minus_predicted_sigma"]
        if ratio < 1 - MISSING_SHARE and sigma < -MISSING_SIGMA:
            if methods & {"forward", "photon"}:
                advice = (": light outside an emitter's aim (glass or a lens between it and its target bends the aimed "
                          "light off it) or high-order ghosts; render with the backward method, whose connections find "
                          "it, or aim at the target's image through the optics")
            elif analysis.get("photon_map") is not None:
                advice = (": scattering surfaces in view are lit through specular optics (a lens, a condenser, a "
                          "mirror fold), which next-event estimation cannot connect through, so backward paths find "
                          "that light only by chance; render with the photon method")
            else:
                advice = (": high-order ghosts, whose glass branches beyond the first splits are drawn by chance; "
                          "render longer, or raise the method's splits")
            out.append(f"the {key} section renders {ratio:.3g} of the brightness-theorem prediction "
                       f"({entry['rendered_cd_m2']:.4g} against {entry['predicted_cd_m2']:.4g} cd/m^2, "
                       f"{-sigma:.3g} combined standard errors below it): the render misses light that reaches the "
                       f"eye through specular optics in paths too rare for its error bars to show{advice}")
    return out


def lit_through_optics(world: World, survey: dict, seed: int, pilot_photons: int = PILOT_PHOTONS,
                       most: int | None = None, stream: int = 1) -> bool:
    """Whether scattering surfaces that chief rays of the ``survey`` (:func:`specular_paths`) end on
    receive more than SPECULAR_SHARE of their light through other surfaces, which the quadrature does
    not follow: where a specular surface blocks their direct view of a light (the quadrature names it),
    or else where a pilot photon map of ``pilot_photons`` (random stream ``seed``, ``stream``) finds such light (a
    screen lit by a mirror whose direct view of the light is blocked by an absorber). ``most``: the pilot
    is looked up at that many of the survey's pixels, evenly spaced (None: every one; the survey
    without the environment then)."""
    n = len(survey["pixels"])
    lum, _, through, _ = per_pixel(survey["paths"], n)
    if np.any(through > SPECULAR_SHARE * (lum + through)):
        return True
    if not any(p["path"].endswith(":scatter") for p in survey["paths"]):
        return False
    pilot = PhotonMap(world, pilot_photons, seed, stream=stream)
    if pilot.grid is None:
        return False
    if most is None:
        with_photons, _, _, _ = per_pixel(specular_paths(world, environment=False, photons=pilot)["paths"], n)
    else:
        pixels = survey["pixels"][evenly(np.arange(n), most)]
        lum, _, _, _ = per_pixel(specular_paths(world, pixels=pixels, environment=False)["paths"], len(pixels))
        with_photons, _, _, _ = per_pixel(specular_paths(world, pixels=pixels, environment=False,
                                                         photons=pilot)["paths"], len(pixels))
    return bool(np.any(with_photons - lum > SPECULAR_SHARE * with_photons))


def analysis_photon_map(world: World, survey: dict, seed: int, photons: int = ANALYSIS_PHOTONS) -> PhotonMap | None:
    """A photon map of ``photons`` particles (random streams ``seed``, ANALYSIS_STREAM) where scattering
    surfaces that the ``survey``'s chief rays end on (a survey without the environment: only the
    emitters' light through optics counts, which photons carry) are lit through other surfaces
    (:func:`lit_through_optics`), else None: what :func:`brightness_theorem` adds to its prediction,
    and what tells a screen HUD's symbols (:func:`tracer.analysis.sections.find_sections`). Both the
    answer and the map are kept for the next analysis of the scene (:data:`KEPT_ANSWERS`, :func:`kept_map`)."""
    if photons <= 0:
        return None
    key = (*world.key, int(seed), min(photons, PILOT_PHOTONS))
    if KEPT_ANSWERS.get(key, lambda: lit_through_optics(world, survey, seed, min(photons, PILOT_PHOTONS),
                                                        most=LISTED_PIXELS, stream=ANALYSIS_PILOT_STREAM)):
        return kept_map(world, photons, seed, ANALYSIS_STREAM)
    return None


#: Photon maps kept by (scene hash, particles, seed, stream): a scene rendered again with its seed (F12
#: after F12 in Blender, a test suite) builds its analysis' map once. A map holds no state between
#: look-ups (tallies are the caller's), so one serves every analysis.
KEPT_MAPS = KeptResults(2)
#: :func:`lit_through_optics`'s answers for the analysis, by (the world's key: scene hash, eye, exact
#: surfaces; seed, pilot particles): the survey it is asked about is the scene's chief rays from that eye,
#: so the key covers what it depends on.
KEPT_ANSWERS = KeptResults(64)


def kept_map(world: World, photons: int, seed: int, stream: int) -> PhotonMap:
    """The photon map of ``world``'s scene for these particles and random stream: kept, or built (the
    map depends on the scene's lights and objects, which its hash covers, not on the eye)."""
    return KEPT_MAPS.get((world.scene.scene_hash, int(photons), int(seed), int(stream)),
                         lambda: PhotonMap(world, photons, seed, stream=stream))


def brightness_theorem(world: World, image_y: np.ndarray, var_y: np.ndarray, environment: bool = True,
                       sections: Sections | None = None, photons: int = ANALYSIS_PHOTONS, seed: int = 0,
                       photon_map: PhotonMap | None = None) -> dict:
    """Compare the render with the brightness-theorem prediction of :mod:`tracer.transport.chains`.

    The sections are :mod:`tracer.analysis.sections`' ("symbol" and "background" where the dominant
    chain crosses an LCD, else "image"), those of the HUD figures. This is a check of the render, not
    a figure to quote: the symbol luminance is the HUD figures' (``hud.symbol_cd_m2``). Up to PUPIL_PIXELS
    evenly spaced pixels of each section are compared (``pixels``; the section has
    ``section_pixels``): the rendered mean over them against a prediction that follows each of them
    with PUPIL_GRID^2 rays from points over the pupil and the pixel (with its standard error)
    (``predicted_cd_m2``; the chief ray's alone is ``predicted_chief_ray_cd_m2``, their ratio
    ``pupil_fill``), and its breakdown by path sums to it ("other paths" included). ``environment``
    False (a method that does not render it) leaves the environment out of the prediction.

    Where the chief rays find a scattering surface lit through other surfaces (:func:`lit_through_optics`:
    a projection lens or a condenser, the paper's sec. 4.1 screen; a mirror fold), a photon map of
    ``photons`` particles (on the random stream ``seed``; :class:`tracer.methods.photon.PhotonMap`)
    follows that light (``photon_map``: :func:`analysis_photon_map`, or the one given), and its error joins
    the prediction's
    (``predicted_photon_standard_error_cd_m2``: the Poisson error of the section's mean from what each
    photon adds to it, which counts the photons the section's points share; for a fixed number of
    particles, and photons of one path taken as independent, it is conservative: 3.1 against a spread of
    2.4 over 12 seeds on a mirror-folded screen). The map's blur over its
    radius is not in it: the comparison is of section means, over which the blur moves little light
    (the edges of a small symbol excepted).

    A section is compared (``rendered_over_predicted``) only where the analysis' assumptions hold;
    otherwise ``valid`` is false and ``not_comparable`` says why: a scattering surface lit through
    specular surfaces whose light the analysis does not follow (``photons`` 0), or by a light closer
    than its quadrature resolves (a backlight right behind a screen).
    """
    # the sections' chains are the survey without the environment: the same call, made once
    known = sections.chains if sections is not None else None
    res = known if known is not None and not environment else specular_paths(world, environment=environment)
    grid_h, grid_w = res["grid"]
    pixels = res["pixels"]
    npts = len(pixels)
    total, _, _, _ = per_pixel(res["paths"], npts)
    listed = res  # the chains listed under "paths": over the grid, or with photons a subset
    if photon_map is None and photons > 0:
        survey = res if not environment else known if known is not None else specular_paths(world, environment=False)
        photon_map = analysis_photon_map(world, survey, seed, photons)
    pmap = photon_map
    if pmap is not None:
        listed = specular_paths(world, pixels=pixels[evenly(np.arange(npts), LISTED_PIXELS)],
                                environment=environment, photons=pmap)
    _, per_path, _, _ = per_pixel(listed["paths"], len(listed["pixels"]))
    out: dict = {
        "method": "every specular branch followed from the pupil (chief rays for the path list; "
                  f"{PUPIL_GRID}x{PUPIL_GRID} points over the pupil for the sections, {PUPIL_GRID_WITH_PHOTONS}x"
                  f"{PUPIL_GRID_WITH_PHOTONS} with a photon map); scattering surfaces lit "
                  "directly by the emitters (deterministic quadrature) and by the environment ("
                  f"{ENV_SAMPLES} directions from its own distribution per point); luminance = product of R and T "
                  "along the chain x luminance behind it" + ("" if environment else "; the environment left out, as "
                                                             "the method does not render it"),
        "assumptions": ("light reaches scattering surfaces directly from the emitters and the environment, not "
                        "through specular optics, " if pmap is None else
                        "light reaches scattering surfaces from the emitters directly or through other surfaces (the "
                        "photon map, blurred over its radius), from the environment directly, ") +
                       "and from no light closer than the quadrature resolves",
        "grid_stride_px": res["stride"],
        "valid": True,
        "not_comparable": [],
        "notes": [],
        "paths": [],
        "photon_map": None if pmap is None else pmap.summary(),
    }
    if pmap is not None:
        out["method"] += ("; the light that reaches scattering surfaces through specular optics from a photon map "
                          "(tracer.methods.photon.PhotonMap), with its Poisson error (conservative)")
    y_img = image_y.reshape(-1)
    v_img = var_y.reshape(-1)
    for p, y in zip(listed["paths"][:8], per_path[:8], strict=True):
        out["paths"].append({"path": p["path"], "pixels_fraction": float(len(np.unique(p["pixel"])) / len(y)),
                             "predicted_mean_cd_m2": float(y.mean()),
                             "transfer_factor_mean": float(p["factor"].mean())})
    if len(listed["paths"]) > 8:
        out["paths"].append({"path": "other paths", "predicted_mean_cd_m2": float(sum(y.mean() for y in per_path[8:]))})
    if not res["paths"]:
        return out
    sections = find_sections(world, None if environment else res) if sections is None else sections
    lcd_paths, grid_lcd = sections.lcd_paths, sections.lcd
    if not lcd_paths:
        out["image_path"] = res["paths"][0]["path"]
    blockers = dict(res["specular_blockers"])
    ends = []  # where the sections' pupil rays end, for the aims' coverage
    for key, mask in sections.masks.items():
        idx = np.nonzero(mask.ravel())[0]
        if len(idx) == 0:
            continue
        sel = evenly(idx, PUPIL_PIXELS)
        grid = PUPIL_GRID if pmap is None else PUPIL_GRID_WITH_PHOTONS
        tally = None if pmap is None else pmap.new_tally()
        pup = specular_paths(world, pixels=pixels[sel], pupil_grid=grid, environment=environment, photons=pmap,
                             photon_tally=tally)
        # the map's error of the mean of the section's rays (each ray's luminance is 1/n^2 of its pixel's)
        photon_se = 0.0 if pmap is None else pmap.sum_standard_error(tally) / (pup["pupil_samples"] * len(sel))
        for k, v in pup["specular_blockers"].items():
            blockers[k] = sorted(set(blockers.get(k, [])) | set(v))
        ends += pup["ends"]
        p_total, p_per_path, p_through, p_coarse = per_pixel(pup["paths"], len(sel))
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
        entry["predicted_standard_error_cd_m2"] = float(math.hypot(math.sqrt(var_pixel.sum()) / len(sel), photon_se))
        if pmap is not None:
            entry["predicted_photon_standard_error_cd_m2"] = photon_se
        if pmap is None:
            chief = float(total[sel].mean())
        else:  # the grid's chief rays gathered no photons
            chief_res = specular_paths(world, pixels=pixels[sel], environment=environment, photons=pmap)
            chief = float(per_pixel(chief_res["paths"], len(sel))[0].mean())
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
        if pmap is not None:  # the grid's chains gathered no photons: the listed pixels' chains did
            named = {p["path"]: p for p in listed["paths"]}
            main, ghost = named.get(main["path"], main), named.get(ghost["path"], ghost)
            main_y, ghost_y = luminance(main["luminance"]), luminance(ghost["luminance"])
            g_sel, m_sel = ghost["lcd"] >= 0.5, main["lcd"] >= 0.5
        g_mean = float(ghost_y[g_sel].mean()) if g_sel.any() else 0.0
        m_mean = float(main_y[m_sel].mean()) if m_sel.any() else 0.0
        out["ghost"] = {
            "path": ghost["path"],
            "predicted_cd_m2": g_mean,
            "ratio_to_symbol": g_mean / m_mean if m_mean > 0 else None,
            # the ghost's place from the symbols', [right, up]: _shift rolls the ghost onto them, rows run down
            "offset_px": [-dx * res["stride"], dy * res["stride"]],
            "offset_mrad": float(math.hypot(dx, dy) * res["stride"] * px_mrad),
        }
    return out
