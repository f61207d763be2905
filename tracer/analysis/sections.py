"""The image's sections by what the eye's chief rays reach along their dominant specular chain (the
chains of :func:`tracer.transport.chains.specular_paths` on the analysis grid): one set of pixel masks
for every figure that speaks of symbols or background, the HUD figures (:mod:`.hud`) and the
brightness-theorem comparison (:mod:`.brightness`) alike.

- Where the dominant chain crosses an LCD (a direct HUD: the eye sees the LCD through the mirror and the
  windshield), "symbol" is the pixels whose chain crosses a clear cell, as do the chains of their four
  neighbouring pixels (an erosion by one pixel, whatever the grid's stride: strokes two pixels wide keep
  their middle), so that stroke edges blurred by the pupil and the pixel are left out: the stroke
  interiors a luminance meter aimed at a stroke reads, the ghost included where it overlaps them.
  "background" is the pixels whose chain and next chain through the LCD (the windshield's ghost) both
  cross black cells, so that the ghost's symbols do not count as black leak, at least
  BACKGROUND_MARGIN_PX pixels from any other: the black level away from the halo that the pupil spreads
  around every stroke.
- Where the eye sees a screen lit through optics and a photon map follows its light
  (:class:`tracer.methods.photon.PhotonMap`: hud-screen, whose LCD the projection lens images onto the
  screen), the photons carry the LCD cell they crossed: "symbol" is the pixels whose chief ray lands on
  the screen where at least SYMBOL_CLEAR_SHARE of the LCD's photons came through clear cells (counted,
  not weighed: where each cell's image falls), eroded by one grid cell; "background" those where none
  did (so that no symbol's light, and no lens ghost's, lies within the map's gather radius: the
  brightness-theorem prediction there is the black leak's), BACKGROUND_MARGIN_PX pixels from any other.
  The photons' span (4 gather radii on the screen) blurs the edges; the erosions leave it out.
- Otherwise (the eye sees a screen, a diffuser or an emitter: no LCD can be followed through a scattering
  surface), "image" is every pixel the brightest chain reaches, eroded by one grid cell.
- "display" is where the dominant chain (through the LCD, else the brightest) reaches, eroded by one grid
  cell with the image's border counted as inside (a display that fills the view keeps its edge).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..transport.chains import specular_paths

#: The background's distance from the symbols' edges (and the display's), pixels: the pupil's blur of a
#: stroke, a pixel or two on the presets, is left out of the black level.
BACKGROUND_MARGIN_PX = 3
#: The share of an LCD's photons through clear cells at a screen point from which it is a symbol (module
#: docstring); background has none.
SYMBOL_CLEAR_SHARE = 0.5


def erode(mask: np.ndarray, border_inside: bool = False) -> np.ndarray:
    """Binary erosion of a 2D mask with the 3 x 3 cross; the image border counts as outside the mask,
    or (``border_inside``) as continuing it (a display that fills the view keeps its edge pixels)."""
    m = np.pad(mask, 1, mode="edge") if border_inside else np.pad(mask, 1, constant_values=False)
    return m[1:-1, 1:-1] & m[:-2, 1:-1] & m[2:, 1:-1] & m[1:-1, :-2] & m[1:-1, 2:]


@dataclass
class Sections:
    """Grid masks (gh, gw) of the sections of the module docstring, and what they were made from.

    chains : the :func:`~tracer.transport.chains.specular_paths` result they come from.
    masks : {"symbol", "background"} where the dominant chain crosses an LCD, else {"image"}.
    display : where the dominant chain reaches (eroded, border inside), or None where no chain does.
    lcd : (gh, gw) the clear fraction of the LCD cell on the dominant chain (NaN off the LCD), or of a
        photon map's LCD photons where the chief ray lands on a screen; else None.
    lcd_paths : the chains that cross an LCD, brightest first (the primary image, then its ghost).
    symbols_from : "lcd_cells" (chains through the LCD), "lcd_cells_via_photons" (a photon map's LCD
        photons on a screen), or None (no symbol and background sections).
    """

    chains: dict
    masks: dict[str, np.ndarray]
    display: np.ndarray | None
    lcd: np.ndarray | None
    lcd_paths: list[dict]
    symbols_from: str | None = None

    @property
    def stride(self) -> int:
        return self.chains["stride"]

    def pixels(self, mask: np.ndarray, shape: tuple[int, int], fill: bool = False) -> np.ndarray:
        """A grid mask as an (H, W) pixel mask of the image ``shape``: grid cell (j, i) is the chief ray
        of pixel (j s + s // 2, i s + s // 2), s the stride; with ``fill`` the cell covers rows j s to
        j s + s - 1 and the same columns (a region), else only the pixels whose chief rays were followed
        are marked (what a section is known to hold)."""
        s = self.stride
        out = np.zeros(shape, bool)
        if fill:
            full = np.kron(mask, np.ones((s, s), bool))
            h, w = min(full.shape[0], shape[0]), min(full.shape[1], shape[1])
            out[:h, :w] = full[:h, :w]
        else:
            out[s // 2::s, s // 2::s] = mask  # the grid of specular_paths: every s-th pixel from s // 2
        return out


def _on_grid(chains: dict, path: dict) -> np.ndarray:
    """The chain's LCD cell values on the grid (NaN where it does not reach)."""
    values = np.full(len(chains["pixels"]), np.nan)
    values[path["pixel"]] = path["lcd"]
    return values.reshape(chains["grid"])


def _interior(world, chains: dict, main: dict, clear: np.ndarray) -> np.ndarray:
    """The grid cells of ``clear`` (gh, gw) whose pixel's four neighbouring pixels' chief rays also reach
    a clear cell along the chain ``main`` (by its path name): an erosion by one pixel. With a stride of
    one pixel that is the grid's own erosion; else the neighbours' chief rays are followed."""
    s = chains["stride"]
    if s == 1:
        return erode(clear)
    eye = world.eye
    w, h = eye.width, eye.height
    cells = np.flatnonzero(clear)
    centre = chains["pixels"][cells]
    y, x = centre // w, centre % w
    ok = np.ones(len(cells), bool)
    neighbours = []
    for dy, dx in ((-1, 0), (1, 0), (0, -1), (0, 1)):
        ny, nx = y + dy, x + dx
        inside = (ny >= 0) & (ny < h) & (nx >= 0) & (nx < w)
        ok &= inside
        neighbours.append(np.where(inside, ny * w + nx, 0))
    around = specular_paths(world, pixels=np.concatenate(neighbours), environment=False)
    value = np.full(4 * len(cells), np.nan)
    for p in around["paths"]:
        if p["path"] == main["path"]:
            value[p["pixel"]] = p["lcd"]
    ok &= np.all((value >= 0.5).reshape(4, len(cells)), axis=0)
    out = np.zeros(clear.size, bool)
    out[cells[ok]] = True
    return out.reshape(clear.shape)


def _screen_clear_share(chains: dict, main: dict, photons) -> np.ndarray:
    """(gh, gw) the share of ``photons``' LCD photons through clear cells where each grid pixel's chief ray
    ends on the scattering surface of the chain ``main`` (its brightest end there; NaN elsewhere)."""
    gh, gw = chains["grid"]
    ends = [e for e in chains["ends"] if e[0] == "material"]
    share = np.full(gh * gw, np.nan)
    if not ends:
        return share.reshape(gh, gw)
    p = np.concatenate([e[2] for e in ends], axis=1)
    weight = np.concatenate([e[4] for e in ends])
    pixel = np.concatenate([e[5] for e in ends]) // chains["pupil_samples"]
    on = np.flatnonzero(np.isin(pixel, main["pixel"]) & (weight > 0))
    order = on[np.lexsort((-weight[on], pixel[on]))]  # by pixel, the brightest end first
    first = order[np.r_[True, pixel[order][1:] != pixel[order][:-1]]] if len(order) else order
    share[pixel[first]] = photons.clear_share(p[:, first])
    return share.reshape(gh, gw)


def find_sections(world, chains: dict | None = None, photons=None) -> Sections:
    """The sections of the HUD's own light (the environment left out: the display is what the HUD's
    chains reach, whatever lies behind it) on the grid of
    :func:`~tracer.transport.chains.specular_paths`; ``chains``, that call's result where known;
    ``photons``, a :class:`tracer.methods.photon.PhotonMap` of the scene where its light reaches a screen
    through optics (the symbols of a screen HUD from its LCD photons, module docstring)."""
    chains = specular_paths(world, environment=False) if chains is None else chains
    paths = chains["paths"]
    gh, gw = chains["grid"]
    if not paths:
        return Sections(chains, {}, None, None, [])
    lcd_paths = [p for p in paths if np.any(np.isfinite(p["lcd"]))]
    main = (lcd_paths or paths)[0]
    reached = np.zeros(gh * gw, bool)
    reached[main["pixel"]] = True
    reached = reached.reshape(gh, gw)
    display = erode(reached, border_inside=True)
    if not lcd_paths:
        if photons is not None and photons.lcd is not None:
            share = _screen_clear_share(chains, main, photons)
            symbol = erode(share >= SYMBOL_CLEAR_SHARE)  # NaN compares False
            background = share == 0  # NaN compares False
            for _ in range(math.ceil(BACKGROUND_MARGIN_PX / chains["stride"])):
                background = erode(background)
            if symbol.any() and background.any():
                return Sections(chains, {"symbol": symbol, "background": background}, display, share, [],
                                "lcd_cells_via_photons")
        return Sections(chains, {"image": erode(reached)}, display, None, [])
    lcd = _on_grid(chains, main)
    # NaN compares False: off the LCD is neither symbol nor background.
    background = lcd < 0.5
    for ghost in lcd_paths[1:2]:
        background &= ~(_on_grid(chains, ghost) >= 0.5)
    for _ in range(math.ceil(BACKGROUND_MARGIN_PX / chains["stride"])):
        background = erode(background)
    masks = {"symbol": _interior(world, chains, main, lcd >= 0.5), "background": background}
    return Sections(chains, masks, display, lcd, lcd_paths, "lcd_cells")
