"""hud-direct: the paper's HUD without a diffuse screen (sec. 3, Fig. 5; sec. 4.2).

Light path: ten LEDs (0.2 x 0.2 mm dies, paper sec. 3) -> a narrow-angle raster scatterer
(Gaussian lobe, sec. 4.2) -> an LCD slide (clear symbols on a 300:1 black, sec. 3) in an absorbing
frame -> a concave mirror -> the inner surface of a 4.76 mm windshield (n = 1.52, both surfaces
traced) -> the eye. Numbers from ../shared/reference/hud-physics.md: virtual image at 2.5 m, field
about 6 x 2 deg, 4 mm pupil, windshield incidence 60-70 deg (here 67 deg), LCD transmission 5 %.

Optical design (units mm, z up, y forward, x to the right; the mirror sits at the origin so that
float32 Embree resolves the optics finely):

- The eye E looks 4 deg down; its chief ray meets the windshield after 800 mm and the mirror after
  another 300 mm. E' is E mirrored in the windshield's inner plane (|E'M| = d2 = 1100 mm).
- The mirror is a patch of the ellipsoid whose foci are E' and the centre LED L (|LM| = d1 = 250 mm):
  it images the LED stigmatically onto the (mirrored) pupil, so an eye at E sees the whole field lit
  through the LCD (the hint of the issue). Its power is P = 1/d1 + 1/d2 in both meridians.
- The LCD lies on the line ML at s_o = 1 / (P + 1/(VID - d2)) = 177.8 mm from the mirror, where the
  mirror forms its virtual image at VID = 2500 mm from the eye (magnification 7.9); its size follows
  from the field of view.
- The scatterer (sigma 3.5 x 3 deg) spreads each LED's light into a patch of the eyebox; a 5 x 2 grid
  of LEDs (pitch 7 x 5 mm, imaged 4.4 times larger) tiles the eyebox with such patches. The scatterer
  aims a share of its light "away from"
  the image of the eye pupil formed by the mirror (at the LED, radius r_pupil d1/d2): the paper's
  directed split toward the entrance pupil of the optical system (sec. 2).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ._build import SceneBuilder, box, disk, frame_bars, frame_matrix, lens, lens_focal_length, rectangle
from .slide import slide_image

NAME = "hud-direct"
SUMMARY = "the paper's direct-view HUD: LEDs, raster scatterer, LCD 300:1, concave mirror, 4.76 mm windshield"

EYE_TO_WINDSHIELD = 800.0
WINDSHIELD_TO_MIRROR = 300.0
LED_TO_MIRROR = 250.0  # d1
VID = 2500.0  # virtual image distance from the eye, mm
LOOK_DOWN_DEG = 4.0
RAKE_DEG = 27.0  # windshield angle from horizontal
MIRROR_INCIDENCE_DEG = 20.0
FOV_DEG = (6.0, 2.0)  # the LCD's virtual image
VIEW_DEG = (7.0, 2.6)  # the retina image: a margin around the display
RESOLUTION = (420, 156)  # 1 arcmin pixels
PUPIL_MM = 4.0
GLASS_MM = 4.76
LED_LUMINANCE = 1.0e9  # cd/m^2 per die (docs/theory/designs.md: what the design's etendue demands)
LED_GRID = (5, 2)  # columns (along x) and rows of LED dies
LED_PITCH = (7.0, 5.0)  # mm; imaged onto the eye plane magnified d2/d1 = 4.4 times
SCATTER_SIGMA_DEG = (3.5, 3.0)
LCD_TRANSMITTANCE = 0.05
CONTRAST = 300.0
MIRROR_R = 0.9
WINDSHIELD_MM = (700.0, 450.0)  # the glass's width and height
#: The target image (tracer.scene.format.TARGET): the design's, over the eyebox its LEDs light
#: (docs/results/designs.md: 120 x 40 mm between the outermost grid points at half luminance).
TARGET = {"distance_mm": VID, "look_down_deg": LOOK_DOWN_DEG, "look_over_deg": 0.0, "fov_deg": list(FOV_DEG),
          "eyebox_mm": [120.0, 40.0], "pgu": "lcd"}


def _rot(v: np.ndarray, axis: np.ndarray, deg: float) -> np.ndarray:
    """Rodrigues rotation of v about a unit axis."""
    a = math.radians(deg)
    return v * math.cos(a) + np.cross(axis, v) * math.sin(a) + axis * (axis @ v) * (1 - math.cos(a))


def windshield_power(radius_x_mm: float, radius_y_mm: float, incidence_deg: float) -> float:
    """The mean power (1/mm) of a windshield's inner surface as a mirror met at ``incidence_deg`` in its
    y-z plane (Coddington: 2 / (R_y cos(theta)) in that plane, 2 cos(theta) / R_x across it; 0 for a
    flat radius)."""
    c = math.cos(math.radians(incidence_deg))
    tangential = 2 / (radius_y_mm * c) if radius_y_mm else 0.0
    sagittal = 2 * c / radius_x_mm if radius_x_mm else 0.0
    return 0.5 * (tangential + sagittal)


def design(radii_mm: tuple[float, float] = (0.0, 0.0)) -> dict:
    """The layout: every point and direction of the optical design (world mm). ``radii_mm``: a curved
    windshield's inner radii [across, up] (hud-direct-curved): the LCD moves to where the mirror and the
    windshield's mean power (:func:`windshield_power`) together image it at VID."""
    mirror = np.zeros(3)
    ld = math.radians(LOOK_DOWN_DEG)
    gaze = np.array([0.0, math.cos(ld), -math.sin(ld)])
    rake = math.radians(RAKE_DEG)
    n_ws = np.array([0.0, -math.sin(rake), -math.cos(rake)])  # inner surface normal, toward the driver
    r1 = gaze - 2 * (gaze @ n_ws) * n_ws  # eye ray after the windshield
    w_point = mirror - WINDSHIELD_TO_MIRROR * r1
    eye = w_point - EYE_TO_WINDSHIELD * gaze
    eye_image = eye - 2 * ((eye - w_point) @ n_ws) * n_ws
    x_axis = np.array([1.0, 0.0, 0.0])
    r2 = _rot(-r1, x_axis, 2 * MIRROR_INCIDENCE_DEG)  # from the mirror toward the LCD and the LED
    led = mirror + LED_TO_MIRROR * r2
    d2 = EYE_TO_WINDSHIELD + WINDSHIELD_TO_MIRROR
    power = 1 / LED_TO_MIRROR + 1 / d2
    incidence = math.degrees(math.acos(abs(gaze @ n_ws)))
    # the windshield's virtual image at VID - a behind it; its object (the mirror's image) at u: 1/u = P + 1/v
    v = VID - EYE_TO_WINDSHIELD
    u = 1 / (windshield_power(*radii_mm, incidence) + 1 / v)
    s_i = u - WINDSHIELD_TO_MIRROR
    s_o = 1 / (power + 1 / s_i)
    magnification = (s_i / s_o) * (v / u)
    lcd_size = [2 * VID * math.tan(math.radians(f) / 2) / magnification for f in FOV_DEG]
    return {"mirror": mirror, "gaze": gaze, "n_ws": n_ws, "w_point": w_point, "eye": eye, "eye_image": eye_image,
            "r1": r1, "r2": r2, "led": led, "s_o": s_o, "magnification": magnification, "lcd_size": lcd_size,
            "lcd_center": mirror + s_o * r2, "d2": d2, "incidence_windshield_deg": incidence}


def ellipsoid_patch(f1: np.ndarray, f2: np.ndarray, center: np.ndarray, size: tuple[float, float],
                    x_axis: np.ndarray, n: tuple[int, int] = (160, 110)):
    """Triangulated patch of the ellipsoid with foci f1, f2 through ``center`` (|X f1| + |X f2| = const),
    over a ``size`` rectangle of its tangent plane: (vertices, faces)."""
    u1 = (f1 - center) / np.linalg.norm(f1 - center)
    u2 = (f2 - center) / np.linalg.norm(f2 - center)
    normal = (u1 + u2) / np.linalg.norm(u1 + u2)
    total = np.linalg.norm(f1 - center) + np.linalg.norm(f2 - center)
    v, f, _ = rectangle(size[0], size[1], n[0], n[1])
    m = np.array(frame_matrix(center, x_axis, normal))
    q = v @ m[:3, :3].T + m[:3, 3]
    s = np.zeros(len(q))
    for _ in range(30):  # Newton along the normal onto the ellipsoid
        x = q + s[:, None] * normal
        a, b = x - f1, x - f2
        la, lb = np.linalg.norm(a, axis=1), np.linalg.norm(b, axis=1)
        g = la + lb - total
        dg = (a @ normal) / la + (b @ normal) / lb
        s -= g / dg
    return q + s[:, None] * normal, f


def ellipsoid_surface(f1: np.ndarray, f2: np.ndarray, center: np.ndarray) -> dict:
    """The exact surface (tracer.scene.format.SURFACE, world coordinates) of the ellipsoid with foci f1,
    f2 through ``center``, as a conic whose vertex is the end of the major axis beyond f2: semi-axes a
    = (|X f1| + |X f2|) / 2 and b, vertex radius R = b^2 / a, conic constant k = -(c / a)^2 (c: half
    the foci's distance). Its sag covers the half of the ellipsoid on f2's side."""
    a = 0.5 * (np.linalg.norm(f1 - center) + np.linalg.norm(f2 - center))
    c = 0.5 * np.linalg.norm(f2 - f1)
    w = (f2 - f1) / (2 * c)
    vertex = 0.5 * (f1 + f2) + a * w
    return {"type": "conic", "radius_mm": (a * a - c * c) / a, "conic": -(c / a) ** 2, "origin": vertex.tolist(),
            "axis": (-w).tolist(), "x_axis": [1.0, 0.0, 0.0]}


#: hud-direct-condenser: a plano-convex condenser (convex face toward the scatterer) CONDENSER_GAP mm
#: in front of the design LED point F2 forms a virtual image of the LEDs at F2, so that the mirror
#: still images them onto the eyebox; the real LEDs sit closer, u = f c / (f + c), on a grid shrunk
#: by the condenser's magnification c / u, so their images tile the eyebox as before.
CONDENSER = {"r": 21.0, "thickness": 9.0, "semi_diameter": 16.0, "ior": 1.52}
CONDENSER_GAP = 20.0
#: The scatterer's aim covers the pupil's images through the windshield's primary reflection and its
#: ghosts 1 to AIM_GHOSTS (ghost k: 2 k - 1 internal reflections).
AIM_GHOSTS = 2
#: Radius (mm) of the condenser's central zone that the LEDs aim at.
CONDENSER_AIM_RADIUS = 12.0


def condenser_layout() -> dict:
    """Where the condenser and the LEDs of hud-direct-condenser go: distances (mm) toward the mirror
    from the design LED point F2, the condenser's focal length and its magnification."""
    c = CONDENSER
    f = lens_focal_length(c["r"], 0.0, c["thickness"], c["ior"])
    # Light enters the flat face and leaves the convex one: the principal planes lie t / n inside the
    # flat face (object side) and at the convex vertex (image side) (Hecht, Optics, sec. 6.1).
    gap = CONDENSER_GAP
    u = f * gap / (f + gap)
    h_object = gap - (c["thickness"] - c["thickness"] / c["ior"])
    return {"f": f, "vertex": gap, "center": gap - 0.5 * c["thickness"], "led": h_object - u, "magnification": gap / u}


def write(folder, pupil_mm: float = PUPIL_MM, resolution=RESOLUTION, condenser: bool = False, name: str = NAME,
          summary: str = SUMMARY, lcd_polariser_deg: float | None = None, film_axis_deg: float | None = None,
          analyser: dict | None = None, windshield: dict | None = None, grid_slide: bool = False) -> Path:
    """The scene folder. ``lcd_polariser_deg``: the LCD's output polariser axis (degrees from its local
    x, which is the world x: 0 gives light that the mirror and the windshield see as s light);
    ``film_axis_deg``: a half-wave retarder film 1 mm in front of the LCD with its fast axis at that
    angle; ``analyser``: the eye's analyser block (polarised sunglasses), presets/hud_direct_polarised.py;
    ``windshield``: fields of a parametric windshield (tracer.scene.windshield.WINDSHIELD: a wedge, radii)
    in place of the flat slab, the same glass at the same place; ``grid_slide``: the LCD shows the
    optical analysis's 5 x 3 field grid in place of the symbols (presets/hud_direct_optics.py)."""
    ws = windshield or {}
    d = design((ws.get("radius_x_mm", 0.0), ws.get("radius_y_mm", 0.0)))
    sb = SceneBuilder(Path(folder), name, summary)
    x_axis = np.array([1.0, 0.0, 0.0])
    r2 = d["r2"]
    # Windshield: a glass slab whose inner face passes through the windshield point.
    if windshield is None:
        slab_center = d["w_point"] - 0.5 * GLASS_MM * d["n_ws"]
        v, f = box(*WINDSHIELD_MM, GLASS_MM)
        sb.add("windshield", (v, f), {"type": "dielectric", "ior": 1.52},
               frame_matrix(slab_center, x_axis, d["n_ws"]))
    else:  # its inner surface through the windshield point, the glass behind it
        sb.add_windshield("windshield", {"size_mm": list(WINDSHIELD_MM), "thickness_mm": GLASS_MM} | windshield,
                          {"type": "dielectric", "ior": 1.52}, frame_matrix(d["w_point"], x_axis, d["n_ws"]))
    # Mirror: the ellipsoid patch with foci E' and the centre LED, and that ellipsoid as its exact surface.
    sb.add("mirror", ellipsoid_patch(d["eye_image"], d["led"], d["mirror"], (170.0, 120.0), x_axis),
           {"type": "mirror", "reflectance": MIRROR_R}, smooth=True,
           surfaces=[ellipsoid_surface(d["eye_image"], d["led"], d["mirror"])])
    # LCD, facing the mirror; its slide is written beside the meshes.
    w_lcd, h_lcd = d["lcd_size"]
    img_rel = "textures/slide.png"
    slide_image(sb.folder / img_rel, grid=grid_slide)
    lcd_v, lcd_f, lcd_uv = rectangle(w_lcd, h_lcd)
    lcd_frame = frame_matrix(d["lcd_center"], x_axis, -r2)
    lcd_material = {"type": "lcd", "image": img_rel, "transmittance": LCD_TRANSMITTANCE, "contrast_ratio": CONTRAST}
    if lcd_polariser_deg is not None:
        lcd_material["polariser"] = {"axis_deg": lcd_polariser_deg}
    sb.add("lcd", (lcd_v, lcd_f), lcd_material, lcd_frame, uv=lcd_uv)
    if film_axis_deg is not None:
        sb.add("half_wave_film", rectangle(w_lcd + 2, h_lcd + 2)[:2], {"type": "retarder", "axis_deg": film_axis_deg},
               frame_matrix(d["lcd_center"] - 1.0 * r2, x_axis, -r2))
    # Opaque frame around the LCD (four bars) so no unmodulated light passes beside it.
    frame_bars(sb, "lcd_frame", (w_lcd, h_lcd), 30.0, lcd_frame)
    # Raster scatterer 3 mm behind the LCD, a little larger than it.
    pupil_image_r = 0.5 * pupil_mm * LED_TO_MIRROR / d["d2"]
    scat_center = d["lcd_center"] + 3.0 * r2
    sb.add("scatterer", rectangle(w_lcd + 6, h_lcd + 6)[:2],
           {"type": "diffuser", "transmittance": 0.9, "sigma_deg": list(SCATTER_SIGMA_DEG),
            "aim": {"target": "pupil_image", "share": 0.8, "mode": "away"}},
           frame_matrix(scat_center, x_axis, -r2))
    # The eye pupil imaged by windshield and mirror: a virtual aperture at the centre LED. The ghost
    # path (outer windshield surface) images it displaced by the plate offset 2 t tan(theta') cos(theta)
    # times the mirror's magnification d1/d2, in the plane of incidence, and the path with 2 k - 1
    # internal reflections (ghost k) by k times that; one disk covers the images of ghosts 0 to K.
    theta = math.radians(d["incidence_windshield_deg"])
    theta_t = math.asin(math.sin(theta) / 1.52)
    ghost_shift = 2 * GLASS_MM * math.tan(theta_t) * math.cos(theta) * LED_TO_MIRROR / d["d2"]
    across = np.cross(x_axis, r2)
    half = 0.5 * AIM_GHOSTS * ghost_shift
    centre = half
    if windshield is not None:
        # A wedge or a curve moves the ghosts' pupil images each its own way (a wedge deviates ghost k by k
        # times its angle): a disk centred on the primary's, reaching twice as far to either side (the
        # analysis's rays then leave within the aim at 99.97 %, tests/analysis/test_aims.py).
        centre, half = 0.0, 4 * half
    sb.add("pupil_image", disk(pupil_image_r + half + 0.2, 64), {"type": "aperture"},
           frame_matrix(d["led"] + centre * across - 0.01 * r2, x_axis, -r2))
    # LED dies facing the scatterer, aimed at it: a grid centred on the design LED position, so that
    # their images tile the eyebox. With a condenser, the dies sit closer on a smaller grid (its virtual
    # image is the design grid).
    led_center, pitch_scale, aim = d["led"], 1.0, {"target": "scatterer", "share": 0.95}
    if condenser:
        lay = condenser_layout()
        c = CONDENSER
        sb.add("condenser", lens(c["r"], 0.0, c["thickness"], c["semi_diameter"]), {"type": "dielectric",
                                                                                   "ior": c["ior"]},
               frame_matrix(d["led"] - lay["center"] * r2, x_axis, -r2), smooth=True)
        # The LEDs aim at the condenser's central zone: its light reaches the scatterer (the whole 32 mm
        # overfills it from 20 mm; aiming at the scatterer itself leaves the light the condenser bends
        # onto it to the own-law samples, 400 times heavier: both measured noisier, hud_direct_condenser.py).
        flat = d["led"] - (lay["center"] - 0.5 * c["thickness"] - 0.05) * r2
        sb.add("condenser_aperture", disk(CONDENSER_AIM_RADIUS, 64), {"type": "aperture"},
               frame_matrix(flat, x_axis, -r2))
        led_center, pitch_scale = d["led"] - lay["led"] * r2, 1.0 / lay["magnification"]
        aim = {"target": "condenser_aperture", "share": 0.95}
    k = 0
    for row in range(LED_GRID[1]):
        for col in range(LED_GRID[0]):
            offset = pitch_scale * ((col - (LED_GRID[0] - 1) / 2) * LED_PITCH[0] * x_axis
                                    + (row - (LED_GRID[1] - 1) / 2) * LED_PITCH[1] * across)
            lv, lf, _ = rectangle(0.2, 0.2)
            sb.add(f"led_{k}", (lv, lf), {"type": "absorber"}, frame_matrix(led_center + offset, x_axis, -r2),
                   emission={"luminance": LED_LUMINANCE, "aim": dict(aim)})
            k += 1
    # Housing below the LED so that nothing escapes backward into the view.
    hv, hf, _ = rectangle(60.0, 40.0)
    sb.add("led_board", (hv, hf), {"type": "absorber"}, frame_matrix(led_center + 1.0 * r2, x_axis, -r2))
    eye = d["eye"]
    eye_block = {"position": eye.tolist(), "gaze": d["gaze"].tolist(), "up": [0.0, 0.0, 1.0],
                 "pupil_diameter_mm": pupil_mm, "focal_length_mm": 16.67, "accommodation_distance_mm": VID,
                 "resolution": list(resolution), "fov_deg": list(VIEW_DEG)}
    if analyser is not None:
        eye_block["analyser"] = dict(analyser)
    return sb.write(
        eye=eye_block,
        methods={"forward": {"max_depth": 24}, "backward": {"max_depth": 24}},
        target=TARGET,
    )
