"""From a film's per-position values to whole images: what each pixel shows.

A film keeps its per-pixel arrays over a layout (tracer.core.film: the pixels sampled so far while
few are, else every pixel). A render's products (the image, its luminance and variance, the
preview's codes) are computed once per position of that layout and then spread over the image by
:class:`ImageFill`, so that a 4K retina stopped after a few batches costs by its samples and by one
sequential pass over its pixels, not by a dozen passes of transcendental functions.

Pixels no sample reached (a render stopped before one sample per pixel) show the value of the
nearest sampled pixel of their row (the left one on a tie), and a row without any sampled pixel that
of the nearest row that has one (the upper one on a tie). Their variance stays 0: unmeasured. The
image is then made of runs: each sampled pixel's value repeated over the pixels nearer to it than to
the next sampled pixel of its row.
"""

from __future__ import annotations

import functools

import numpy as np

from ..core.film import Film, summarise_counts


def _nearest(known: np.ndarray) -> np.ndarray:
    """For each position of the 1-D ``known`` (n,), the index of the nearest known one (the lower on a
    tie; n where none is known)."""
    n = len(known)
    at = np.arange(n)
    left = np.maximum.accumulate(np.where(known, at, -1))
    right = np.minimum.accumulate(np.where(known, at, n)[::-1])[::-1]
    use_right = (left < 0) | ((right < n) & (at - left > right - at))
    return np.where(use_right, right, left)


class ImageFill:
    """How per-position values of ``film``'s layout become (H, W) images, and the statistics of those
    images computed from the per-position values and how many pixels show each (:meth:`population`).

    Where batches covered part of the image (the film counts samples per pixel), the pixels no sample
    reached, ``unsampled``, show their nearest sampled neighbour's value (see the module's docstring);
    all pixels are unsampled when no pixel was sampled (the image is then black). Otherwise every
    pixel shows the film's own value, zero where nothing landed. ``counts``: (mean, fewest, most)
    samples per pixel where batches covered part of the image, else None."""

    def __init__(self, film: Film):
        self.film = film
        self.shape = (film.height, film.width)
        self.unsampled = 0
        self.counts = None
        #: Samples through the pixel at each position of the film's layout where batches covered part of
        #: the image, else None.
        self.per_position: np.ndarray | None = None
        self._runs = None  # (positions (k,), lengths (k,)): the image, row by row, as runs of one value
        found = film.layout_sample_counts()
        if found is None:
            return
        self.per_position, outside = found
        self.counts = summarise_counts(self.per_position, outside, film.pixels)
        if outside > 0:  # every pixel was sampled
            return
        sampled = np.flatnonzero(self.per_position > 0)
        self.unsampled = film.pixels - len(sampled)
        if 0 < self.unsampled < film.pixels:
            pixels = film.layout_pixels()[sampled]
            order = np.argsort(pixels, kind="stable")
            self._runs = self._make_runs(pixels[order], sampled[order])

    def _make_runs(self, known: np.ndarray, positions: np.ndarray):
        """The runs of an image whose sampled pixels are ``known`` (flat, sorted), at ``positions``."""
        h, w = self.shape
        row, col = np.divmod(known, w)
        first = np.ones(len(known), bool)
        first[1:] = row[1:] != row[:-1]  # the first sampled pixel of its row
        last = np.ones(len(known), bool)
        last[:-1] = first[1:]
        # a sampled pixel's run starts after the midpoint to the previous one in its row (ties go left)
        start = np.zeros(len(known), np.int64)
        start[~first] = (col[:-1][~first[1:]] + col[1:][~first[1:]]) // 2 + 1
        end = np.empty(len(known), np.int64)
        end[:-1] = start[1:]
        end[last] = w
        lengths = end - start
        sampled_rows = np.zeros(h, bool)
        sampled_rows[row] = True
        if sampled_rows.all():
            return positions, lengths
        # rows without a sampled pixel repeat the runs of the nearest row that has one
        source = _nearest(sampled_rows)
        runs_in_row = np.bincount(row, minlength=h)
        first_run = np.cumsum(runs_in_row) - runs_in_row
        take = runs_in_row[source]
        order = np.repeat(first_run[source] - np.cumsum(take) + take, take) + np.arange(int(take.sum()))
        return positions[order], lengths[order]

    def image(self, values: np.ndarray) -> np.ndarray:
        """(H, W, ...) from per-position ``values`` (layout, ...): each pixel its own value, or its
        nearest sampled neighbour's (row by row, contiguous: a table of several channels becomes an
        interleaved image in one pass)."""
        if self._runs is None:
            return self.as_film(values)
        positions, lengths = self._runs
        return np.repeat(values[positions], lengths, axis=0).reshape(self.shape + values.shape[1:])

    def as_film(self, values: np.ndarray) -> np.ndarray:
        """(H, W, ...) from per-position ``values`` (layout, ...) that no pixel borrows (a variance: a
        filled pixel is unmeasured): zero at the pixels not in the layout."""
        return self.film.to_pixels(values, axis=0).reshape(self.shape + values.shape[1:])

    def place(self, image: np.ndarray, channel: int, values: np.ndarray):
        """Write per-position ``values`` (layout,) into channel ``channel`` of ``image`` (H, W, C),
        contiguous, at the pixels of the layout (the other pixels keep theirs)."""
        image.reshape(self.film.pixels, image.shape[-1])[self.film.layout_pixels(), channel] = values

    def population(self, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The pixels of :meth:`image` (``values``) as (distinct values (k,), how many pixels show each
        (k,), float): the per-position values, each with the pixels that show it, and a 0 for the
        pixels outside the layout that show nothing. A statistic over the image (a mean, a maximum,
        the share of clipped pixels) is the same statistic over this weighted population."""
        weights = self._weights
        if len(weights) > len(values):  # the pixels that show nothing
            return np.append(values, 0), weights
        return values, weights

    @functools.cached_property
    def _weights(self) -> np.ndarray:
        """How many pixels show each position's value (layout,), then those that show nothing where
        there are any (:meth:`population`)."""
        size = self.film.layout_pixels().size
        if self._runs is not None:
            positions, lengths = self._runs
            weights = np.bincount(positions, weights=lengths, minlength=size)
        else:
            weights = np.ones(size)
        blank = self.film.pixels - int(weights.sum())
        return np.append(weights, blank) if blank else weights
