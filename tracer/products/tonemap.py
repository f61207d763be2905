"""Tone mapping of rendered luminance images into 8-bit sRGB previews.

The preview shows the scene as an eye adapted to it would judge it, with Ward's
contrast-based scale factor: one linear factor for the whole image, so luminance ratios (the
contrast of a HUD symbol against its background, for instance) are kept exactly up to
display white.

References
----------
G. Ward, "A contrast-based scalefactor for luminance display", in P. Heckbert (ed.),
Graphics Gems IV, Academic Press, 1994, doi:10.1016/B978-0-12-336156-1.50054-9.

E. Reinhard, M. Stark, P. Shirley, J. Ferwerda, "Photographic tone reproduction for digital
images", ACM Transactions on Graphics 21(3), 2002, pp. 267-276, doi:10.1145/566654.566575
(log-average luminance, their equation 1).
"""

from __future__ import annotations

import numpy as np

from ..core.imageio import srgb_encode
from ..core.units import luminance

#: The display white luminance (cd/m^2) previews are made for (Ward's L_dmax).
DISPLAY_MAX_LUMINANCE = 100.0


def log_average_luminance(Y, delta: float = 1e-4, weights=None) -> float:
    """Log-average ("key") luminance of an image, ``exp(mean(ln(delta + Y)))``.

    Reinhard et al. 2002, equation 1 (doi:10.1145/566654.566575); Ward 1994 adapts the eye
    to the same quantity.

    Parameters
    ----------
    Y : array_like, shape (H, W)
        Luminance, cd/m^2, >= 0. Non-finite values (NaN, +-Inf) are ignored.
    delta : float
        Small positive luminance, cd/m^2, that keeps the logarithm of black pixels finite.
    weights : array_like of Y's shape, or None
        How many pixels show each value of ``Y`` (an image given as its distinct values:
        tracer.products.fill.ImageFill.population); None: one each.

    Returns
    -------
    float
        Log-average luminance, cd/m^2. An image with no light (all zero), or with no finite
        value at all, gives ``delta``.

    Raises
    ------
    ValueError
        ``delta`` is not finite and positive, or a finite luminance is negative.
    """
    if not (np.isfinite(delta) and delta > 0):
        raise ValueError(f"delta must be finite and > 0, got {delta}")
    Y = np.asarray(Y, dtype=np.float64)
    finite = np.isfinite(Y)
    w = None if weights is None else np.asarray(weights, dtype=np.float64)[finite]
    Y = Y[finite]
    if np.any(Y < 0):
        raise ValueError("luminance must be >= 0")
    if Y.size == 0 or (w is not None and not w.sum() > 0):
        return float(delta)
    return float(np.exp(np.average(np.log(delta + Y), weights=w)))


def ward_scale_factor(L_wa: float, L_dmax: float = DISPLAY_MAX_LUMINANCE) -> float:
    """Ward's contrast-based scale factor m (Ward 1994, doi:10.1016/B978-0-12-336156-1.50054-9).

    ``m = [(1.219 + L_da ** 0.4) / (1.219 + L_wa ** 0.4)] ** 2.5`` with the display adaptation
    luminance ``L_da = L_dmax / 2``. A world luminance L is shown with display luminance
    ``m L``, i.e. with the display input value ``m L / L_dmax`` (1 is display white).

    Parameters
    ----------
    L_wa : float
        World adaptation luminance, cd/m^2, >= 0.
    L_dmax : float
        Maximum (white) luminance of the display, cd/m^2, > 0.

    Returns
    -------
    float
        m, dimensionless.

    Raises
    ------
    ValueError
        ``L_wa`` negative or ``L_dmax`` not positive, or either not finite.
    """
    if not (np.isfinite(L_wa) and L_wa >= 0):
        raise ValueError(f"adaptation luminance must be finite and >= 0, got {L_wa}")
    if not (np.isfinite(L_dmax) and L_dmax > 0):
        raise ValueError(f"display maximum luminance must be finite and > 0, got {L_dmax}")
    L_da = L_dmax / 2.0
    return float(((1.219 + L_da**0.4) / (1.219 + L_wa**0.4)) ** 2.5)


def tonemap_ward(rgb, adaptation_luminance: float | None = None, L_dmax: float = DISPLAY_MAX_LUMINANCE):
    """8-bit sRGB preview of a linear RGB luminance image, with Ward's scale factor.

    Every channel is multiplied by ``m / L_dmax`` (:func:`ward_scale_factor`), values above
    display white (1) are clipped per channel, and the result is sRGB-encoded
    (IEC 61966-2-1) and rounded to 8 bits. Below white, luminance ratios are preserved.

    Parameters
    ----------
    rgb : array_like, shape (H, W, 3)
        Linear Rec.709 RGB, scaled so that ``Y = 0.2126 R + 0.7152 G + 0.0722 B`` is the
        luminance in cd/m^2; finite and >= 0.
    adaptation_luminance : float or None
        World adaptation luminance L_wa, cd/m^2; ``None`` uses the log-average luminance of
        the image (:func:`log_average_luminance`).
    L_dmax : float
        Display white luminance, cd/m^2.

    Returns
    -------
    png : np.ndarray, shape (H, W, 3), uint8
        sRGB-encoded preview, row 0 the top row.
    info : dict
        ``adaptation_luminance`` (cd/m^2), ``scale_factor`` (m), ``display_max_luminance``
        (L_dmax, cd/m^2), ``clipped_fraction`` (fraction of pixels with any channel above
        display white) and ``clipping`` (a sentence saying how such pixels are shown).

    Raises
    ------
    ValueError
        ``rgb`` is not a non-empty (H, W, 3) array, or holds a non-finite or negative value
        (a bug upstream: a preview never hides one).
    """
    rgb = np.asarray(rgb, dtype=np.float64)
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.size == 0:
        raise ValueError(f"rgb must be a non-empty (H, W, 3) array, got shape {rgb.shape}")
    check_preview_input(rgb)
    if adaptation_luminance is None:
        adaptation_luminance = log_average_luminance(luminance(rgb))
    png, clipped = ward_codes(rgb, adaptation_luminance, L_dmax)
    return png, ward_info(adaptation_luminance, L_dmax, float(np.mean(clipped)))


def check_preview_input(rgb: np.ndarray):
    """ValueError for a non-finite or negative value (a bug upstream: a preview never hides one)."""
    if not np.all(np.isfinite(rgb)):
        raise ValueError("rgb holds non-finite values (NaN or Inf)")
    if np.any(rgb < 0):
        raise ValueError("rgb holds negative values")


def ward_codes(rgb: np.ndarray, adaptation_luminance: float,
               L_dmax: float = DISPLAY_MAX_LUMINANCE) -> tuple[np.ndarray, np.ndarray]:
    """The 8-bit sRGB codes (..., 3) uint8 of linear RGB ``rgb`` (..., 3), cd/m^2, for an eye adapted to
    ``adaptation_luminance`` (cd/m^2): Ward's scale factor, each channel clipped at display white, sRGB
    encoding (:func:`tonemap_ward`); and whether each pixel (...) was clipped. Pixel by pixel, so that
    a render computes them once per sampled pixel (tracer.products.render); ``rgb`` passed
    :func:`check_preview_input`."""
    m = ward_scale_factor(adaptation_luminance, L_dmax)
    # in float32: 8-bit codes need 1e-3 of the range, and a 4K preview takes a third of the time and memory
    display = np.multiply(rgb, np.float32(m / L_dmax), dtype=np.float32)
    clipped = np.any(display > 1.0, axis=-1)
    np.minimum(display, np.float32(1.0), out=display)
    encoded = srgb_encode(display)
    del display
    encoded *= np.float32(255.0)
    return np.rint(encoded, out=encoded).astype(np.uint8), clipped


def ward_info(adaptation_luminance: float, L_dmax: float, clipped_fraction: float) -> dict:
    """The preview's figures in a report (:func:`tonemap_ward`'s ``info``)."""
    return {
        "adaptation_luminance": float(adaptation_luminance),
        "scale_factor": ward_scale_factor(adaptation_luminance, L_dmax),
        "display_max_luminance": float(L_dmax),
        "clipped_fraction": clipped_fraction,
        "clipping": (
            f"each channel clipped at display white (L_dmax = {L_dmax:g} cd/m^2 after Ward "
            "scaling); hue shifts in clipped pixels"
        ),
    }


def adaptation_luminance(y: np.ndarray, mode: str = "log_average", weights: np.ndarray | None = None) -> float:
    """The luminance (cd/m^2) the eye adapts to, over the pixels that receive light: their log-average
    (``mode`` "log_average", Ward 1994 and Reinhard et al. 2002, eq. 1) or their arithmetic mean
    ("mean", the "average luminance" of the paper, sec. 4.1). Pixels that receive none (no environment,
    nothing in view) are left out: an eye looking at a HUD in the dark adapts to what it sees, not to
    an infinitely dark void. The log-average weighs a bright sun or HUD symbol less than the mean.
    ``weights``: how many pixels show each value of ``y`` (:func:`log_average_luminance`)."""
    if weights is not None:  # the values some pixel shows
        shown = weights > 0
        y, weights = y[shown], weights[shown]
    lit = y > 1e-9 * max(float(y.max()), 1e-300)
    w = None if weights is None else weights[lit]
    if mode == "mean":
        return float(np.average(y[lit], weights=w)) if lit.any() else 0.0
    return log_average_luminance(y[lit], weights=w) if lit.any() else log_average_luminance(y, weights=weights)
