"""Scene folders written or edited by hand, shared by several test files: scene.json edits, a panel in
view, an LCD edge, a glass plate met at 67 deg (a windshield), a screen lit through glass, analytic-mirror
behind a glass block, and hud-direct at a ninth of its pixels under a sky."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from presets._build import SceneBuilder, box, disk, frame_matrix, rectangle, write_obj
from tests.support.optics import N_GLASS
from tracer.core.imageio import write_png


def edit_json(folder: Path, fn):
    """Edit the scene folder's scene.json in place: ``fn`` changes the parsed JSON."""
    p = Path(folder) / "scene.json"
    data = json.loads(p.read_text())
    fn(data)
    p.write_text(json.dumps(data))


def set_field(path, value):
    """An edit setting the key path (e.g. ("eye", "pupil_diameter_mm")) of scene.json to ``value``."""
    def edit(d):
        node = d
        for k in path[:-1]:
            node = node[k]
        node[path[-1]] = value
    return edit


def panel_in_view(folder, panel_mm: float, pupil_mm: float, screen: bool = False):
    """A Lambertian panel 50 mm in front of the eye (behind a diffuse screen at 40 mm if ``screen``),
    without aiming: the plain methods, as the paper describes them."""
    sb = SceneBuilder(folder, "panel", "a panel in view")
    sb.add("panel", rectangle(panel_mm, panel_mm)[:2], {"type": "emitter", "luminance": 100.0},
           frame_matrix([0, 50, 0], [1, 0, 0], [0, -1, 0]))
    if screen:
        sb.add("screen", rectangle(100.0, 100.0)[:2], {"type": "lambertian_transmitter", "transmittance": 0.8},
               frame_matrix([0, 40, 0], [1, 0, 0], [0, -1, 0]))
    return sb.write(eye={"position": [0, 0, 0], "gaze": [0, 1, 0], "up": [0, 0, 1], "pupil_diameter_mm": pupil_mm,
                         "accommodation_distance_mm": 50.0, "resolution": [8, 8], "fov_deg": [90.0, 90.0]})


def lcd_edge_scene(folder, share=0.9):
    """A backlight behind an LCD with one vertical edge (left half clear), in direct view at 300 mm."""
    folder.mkdir(parents=True)
    img = np.zeros((8, 64, 3), np.uint8)
    img[:, :32] = 255
    write_png(folder / "edge.png", img)
    sb = SceneBuilder(folder, "lcd-edge", "an LCD edge seen directly")
    v, f, uv = rectangle(20.0, 10.0)
    sb.add("lcd", (v, f), {"type": "lcd", "image": "edge.png", "transmittance": 0.5, "contrast_ratio": 300},
           frame_matrix([0.3, 300, 0], [1, 0, 0], [0, -1, 0]), uv=uv)
    sb.add("backlight", rectangle(30.0, 20.0)[:2], {"type": "emitter", "luminance": 1000.0,
                                                    "aim": {"target": "eye", "share": share}},
           frame_matrix([0, 310, 0], [1, 0, 0], [0, -1, 0]))
    return sb.write(eye={"position": [0, 0, 0], "gaze": [0, 1, 0], "up": [0, 0, 1], "pupil_diameter_mm": 3.0,
                         "focal_length_mm": 16.67, "accommodation_distance_mm": 300.0,
                         "resolution": [40, 8], "fov_deg": [1.2, 0.24]})


def lcd_screen_scene(folder, gap: float = 0.5, contrast: float = 100.0):
    """A backlight behind an LCD with one vertical edge (left half clear, as in :func:`lcd_edge_scene`)
    imaged onto a diffuse screen ``gap`` mm in front of it (a Lambertian transmitter, tau 0.8), seen at
    300 mm: a screen HUD without the projection lens. The screen sees the backlight through the LCD, so
    the analysis follows that light with a photon map, whose photons carry the cell they crossed."""
    folder.mkdir(parents=True)
    img = np.zeros((8, 64, 3), np.uint8)
    img[:, :32] = 255
    write_png(folder / "edge.png", img)
    sb = SceneBuilder(folder, "lcd-screen", "an LCD edge on a diffuse screen")
    sb.add("screen", rectangle(40.0, 20.0)[:2], {"type": "lambertian_transmitter", "transmittance": 0.8},
           frame_matrix([0, 300, 0], [1, 0, 0], [0, -1, 0]))
    v, f, uv = rectangle(20.0, 10.0)
    sb.add("lcd", (v, f), {"type": "lcd", "image": "edge.png", "transmittance": 0.5, "contrast_ratio": contrast},
           frame_matrix([0, 300 + gap, 0], [1, 0, 0], [0, -1, 0]), uv=uv)
    sb.add("backlight", rectangle(30.0, 20.0)[:2], {"type": "emitter", "luminance": 1000.0},
           frame_matrix([0, 310, 0], [1, 0, 0], [0, -1, 0]))
    return sb.write(eye={"position": [0, 0, 0], "gaze": [0, 1, 0], "up": [0, 0, 1], "pupil_diameter_mm": 3.0,
                         "focal_length_mm": 16.67, "accommodation_distance_mm": 300.0,
                         "resolution": [48, 24], "fov_deg": [3.6, 1.8]})


def plate_scene(folder, thickness=4.76, emitter=None, analyser=None, strip=False, resolution=(4, 4),
                fov=(0.1, 0.1), polarisation=None, extra=None):
    """A glass plate met at 67 deg reflecting an emitter into the eye (a windshield). ``strip``: a
    3 mm strip 150 mm from the plate, whose primary and ghost images fall on different rows of a tall
    view (with a thick plate); otherwise a 40 mm panel that covers every image. The emitter aims at
    the eye's image in the plate (forward tracing); ``emitter`` adds fields to its emission block."""
    sb = SceneBuilder(folder, "plate", "a glass plate reflecting an emitter")
    theta = math.radians(67.0)
    normal = np.array([0.0, -math.cos(theta), math.sin(theta)])
    hit = np.array([0.0, 200.0, 0.0])
    sb.add("plate", box(300.0, 300.0, thickness), {"type": "dielectric", "ior": N_GLASS},
           frame_matrix(hit - 0.5 * thickness * normal, [1, 0, 0], normal))
    gaze = np.array([0.0, 1.0, 0.0])
    r = gaze - 2 * (gaze @ normal) * normal
    center = hit + 150.0 * r
    em = {"luminance": 1000.0, "aim": {"target": "eye_image", "share": 0.9}} | (emitter or {})
    size = (40.0, 3.0) if strip else (40.0, 40.0)
    sb.add("emitter", rectangle(*size)[:2], {"type": "absorber"}, frame_matrix(center, [1, 0, 0], -r), emission=em)
    e_img = -2 * ((-hit) @ normal) * normal
    sb.add("eye_image", disk(15.0, 64), {"type": "aperture"}, frame_matrix(e_img, [1, 0, 0], r))
    for name, mesh, material, frame in extra or ():
        sb.add(name, mesh, material, frame)
    eye = {"position": [0.0, 0.0, 0.0], "gaze": gaze.tolist(), "up": [0, 0, 1], "pupil_diameter_mm": 4.0,
           "accommodation_distance_mm": 350.0, "resolution": list(resolution), "fov_deg": list(fov)}
    if analyser is not None:
        eye["analyser"] = analyser
    blocks = {"eye": eye} | ({"polarisation": polarisation} if polarisation else {})
    return sb.write(**blocks)


#: A third of hud-direct's retina in each direction: the same optics, a ninth of the pixels.
LOW = (140, 52)


def sky(folder, cd_m2: float = 1000.0):
    """A uniform sky of ``cd_m2`` as the scene's environment."""
    edit_json(folder, lambda d: d.update(environment={"type": "uniform", "luminance": cd_m2}))


def condenser_scene(folder):
    """A rear-projection screen (Lambertian transmitter) lit by an LED behind it only through a glass
    block: the screen's direct view of the LED is blocked by a dielectric, which the analysis'
    quadrature does not follow."""
    sb = SceneBuilder(folder, "condenser", "a screen lit through glass")
    sb.add("screen", rectangle(60, 60), {"type": "lambertian_transmitter", "transmittance": 0.8},
           frame_matrix([0, 0, 0], [1, 0, 0], [0, 0, 1]))
    sb.add("glass", box(80, 80, 10), {"type": "dielectric", "ior": 1.5},
           frame_matrix([0, 0, -30], [1, 0, 0], [0, 0, 1]))
    sb.add("led", disk(3.0, 32), {"type": "absorber"}, frame_matrix([0, 0, -60], [1, 0, 0], [0, 0, 1]),
           emission={"luminance": 1e6})
    return sb.write(eye={"position": [0, 0, 200], "gaze": [0, 0, -1], "up": [0, 1, 0], "pupil_diameter_mm": 4.0,
                         "focal_length_mm": 16.67, "accommodation_distance_mm": 200.0, "resolution": [16, 16],
                         "fov_deg": [12.0, 12.0]})


def folded_screen_scene(folder, image: bool = False, rho: float = 0.9, luminance: float = 1e5, baffle: bool = True):
    """A rear-projection screen (Lambertian transmitter, tau 0.8, at z = 0) lit from below by a disc
    emitter (radius 15 mm, facing down and to the right) through a horizontal mirror (reflectance
    ``rho``) at z = -100; an absorbing baffle at z = -30 blocks the emitter's direct view of the
    screen and leaves its beam to the mirror and the mirror's beam to the screen clear. The eye looks
    down at the screen from 300 mm, focused 600 mm away (beyond the screen, so that the field points'
    landing points move with the eye). ``image`` true: the same light without mirror and baffle, the
    emitter at its mirror image (facing up and to the right) with luminance rho x ``luminance``, which
    the analysis' quadrature follows directly: a second method for the folded scene's photon map.
    ``baffle`` false: no baffle, so the screen also sees the emitter directly (in the image scene too,
    the emitter beside its image)."""
    sb = SceneBuilder(folder, "folded-screen" + ("-image" if image else ""), "a screen lit through a mirror fold")
    sb.add("screen", rectangle(60, 60), {"type": "lambertian_transmitter", "transmittance": 0.8},
           frame_matrix([0, 0, 0], [1, 0, 0], [0, 0, 1]))
    s = 1 / math.sqrt(2)
    if image:
        sb.add("led_image", disk(15.0, 64), {"type": "absorber"},
               frame_matrix([-200, 0, -150], [s, 0, -s], [s, 0, s]), emission={"luminance": rho * luminance})
    if image and not baffle:
        sb.add("led", disk(15.0, 64), {"type": "absorber"}, frame_matrix([-200, 0, -50], [s, 0, s], [s, 0, -s]),
               emission={"luminance": luminance})
    if not image:
        sb.add("mirror", rectangle(120, 150), {"type": "mirror", "reflectance": rho},
               frame_matrix([-130, 0, -100], [1, 0, 0], [0, 0, 1]))
        if baffle:
            sb.add("baffle", rectangle(220, 400), {"type": "absorber"},
                   frame_matrix([-190, 0, -30], [1, 0, 0], [0, 0, 1]))
        sb.add("led", disk(15.0, 64), {"type": "absorber"}, frame_matrix([-200, 0, -50], [s, 0, s], [s, 0, -s]),
               emission={"luminance": luminance, "aim": {"target": "mirror", "share": 0.95}})
    return sb.write(eye={"position": [0, 0, 300], "gaze": [0, 0, -1], "up": [0, 1, 0], "pupil_diameter_mm": 4.0,
                         "focal_length_mm": 16.67, "accommodation_distance_mm": 600.0, "resolution": [32, 32],
                         "fov_deg": [8.0, 8.0]})


def mirror_behind_glass(preset):
    """analytic-mirror (a 1000 cd/m^2 panel seen in a mirror of R 0.85, its aim at the pupil's mirror
    image) with a 20 mm glass block (n 1.5) across the view: the block brings the pupil's image
    t (1 - 1/n) = 6.7 mm nearer, so 18 % of the light that reaches the eye leaves the panel outside its
    aim, and forward tracing finds it only in rare unaimed particles."""
    folder = preset("analytic-mirror", resolution=(32, 24))
    v, f = box(80.0, 20.0, 80.0)
    write_obj(folder / "meshes" / "glass.obj", v + [0.0, 110.0, 0.0], f)
    edit_json(folder, lambda d: d["objects"].append({"name": "glass", "mesh": "meshes/glass.obj",
                                                     "material": {"type": "dielectric", "ior": 1.5}}))
    return folder


def mirror_cap(radius: float, half: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    """A square patch (2 ``half`` mm wide, n x n cells) of the sphere of ``radius`` mm whose vertex is
    at the origin and whose centre is at (0, 0, radius): (vertices, faces), normals +z at the vertex."""
    v, f, _ = rectangle(2 * half, 2 * half, n, n)
    v[:, 2] = radius - np.sqrt(radius * radius - v[:, 0] ** 2 - v[:, 1] ** 2)
    return v, f


def sphere_mirror_scene(folder, radius: float = 500.0, half: float = 60.0, n: int = 12, surfaces=None,
                        transform=None):
    """A concave spherical mirror patch (:func:`mirror_cap`) with smooth normals seen from 300 mm on its
    axis, with the exact ``surfaces`` given (default: its sphere)."""
    sb = SceneBuilder(Path(folder), "sphere-mirror", "a concave spherical mirror patch")
    if surfaces is None:
        surfaces = [{"type": "sphere", "radius_mm": radius}]
    sb.add("mirror", mirror_cap(radius, half, n), {"type": "mirror", "reflectance": 1.0}, transform, smooth=True,
           surfaces=surfaces)
    return sb.write(eye={"position": [0, 0, 300], "gaze": [0, 0, -1], "up": [0, 1, 0], "pupil_diameter_mm": 4,
                         "resolution": [8, 8], "fov_deg": [10, 10]})
