"""The film: per-pixel sums of Monte Carlo estimates of apparent luminance (cd/m^2), in named
components, with a variance that is honest for every estimator.

Components. Each component has its own normaliser: a camera (backward) component counts samples per
pixel, a light (forward) component counts particles emitted, whose splats land anywhere. The image is
the sum over components of sum / normaliser. A method may split its estimate into several components
with the same normaliser (the backward method keeps what next-event connections bring apart from
what paths that hit a source bring, so the report can give the share of each).

Variance from replicates. A batch is made of R independent replicates (a backward batch's sample
passes over all pixels, a forward batch's particles dealt round-robin into groups); each replicate r
gives a whole image m_r of its own, m_r = sum over components of (replicate's sum) / (replicate's
normaliser). The film keeps per pixel the sums of m_r and of m_r^2 over all replicates of all
batches, so the variance of the mean follows from the spread of the replicates,
var = (sum m_r^2 / R - mean^2) / (R - 1), whatever the estimator: a splat that lands in several
pixels, a connection, a photon. Replicates have equal normalisers, so the mean of the m_r is the
image itself.

Sums merge exactly: a film from another process adds to this one term by term (tracer.runtime.parallel adds
batches in batch order, so the same batches give the same image bit for bit). A per-pixel array of a
batch that is zero in most pixels (a forward batch: a few thousand particles on the retina; a
backward batch's paths that hit a source) travels as its non-zero columns only (:class:`Columns`;
on hud-direct a forward batch's film is 0.14 MiB, a backward one's 3.5 MiB); adding it gives the
same bits as adding the dense array, whose other columns are zeros.

Layout. A film keeps its per-pixel arrays over the pixels sampled so far, in the order they were
first sampled (a compact layout: memory and merges cost by the samples, not by the retina's pixels),
until those are :data:`COMPACT_SHARE` of the retina, and from then on over every pixel. A render
stopped after a few batches of a 4K retina (backward batches spread their samples over the whole
image) so holds a few MB, not 0.7 GB, and its merges touch no page they do not write. The layout
changes no number: every pixel's sums are the same additions in the same order.

Groups. Components traced independently of each other (the hybrid method's channels: each its own
method, its own random streams, its own replicates) form groups; each group keeps its own replicate
sums, and the image's variance is the sum of the groups' variances (independent estimates add).
"""

from __future__ import annotations

import numpy as np

from .units import Y_WEIGHTS, luminance3

#: A batch's per-pixel array travels as its non-zero columns (:class:`Columns`) when they are fewer
#: than this share of the pixels.
SPARSE_SHARE = 0.25

#: A film keeps its arrays over the pixels sampled so far until they are this share of the retina,
#: then over every pixel (:class:`Film`).
COMPACT_SHARE = 0.25


class Columns:
    """The columns ``idx`` (m,) of a per-pixel array whose other columns are zero: ``values`` (..., m)."""

    __slots__ = ("idx", "values")

    def __init__(self, idx: np.ndarray, values: np.ndarray):
        self.idx, self.values = idx, values

    def __getstate__(self):
        return self.idx, self.values

    def __setstate__(self, state):
        self.idx, self.values = state


def _add(total: np.ndarray, a, place) -> None:
    """``total += a`` for a dense array or :class:`Columns`, whose pixels are at ``place(pixels)`` of
    ``total`` (the same bits either way: x + 0 = x)."""
    if isinstance(a, Columns):
        total[..., place(a.idx)] += a.values
    else:
        total += a


def summarise_counts(per_position: np.ndarray, outside: int, pixels: int) -> tuple[float, int, int]:
    """The mean, fewest and most of a count per pixel of a film's layout, ``per_position`` (layout,),
    that is ``outside`` at the other of the ``pixels`` pixels."""
    rest = pixels - len(per_position)
    lows = ([int(per_position.min())] if per_position.size else []) + ([outside] if rest else [])
    highs = ([int(per_position.max())] if per_position.size else []) + ([outside] if rest else [])
    return (float(per_position.sum(dtype=np.int64)) + float(outside) * rest) / pixels, min(lows), max(highs)


def _filled(shape: tuple, fill, dtype) -> np.ndarray:
    """An array of ``fill`` (zeros left to the kernel: pages nobody writes cost no memory)."""
    return np.zeros(shape, dtype) if fill == 0 else np.full(shape, fill, dtype)


def _placed(values: np.ndarray, size: int, at, fill, axis: int = -1) -> np.ndarray:
    """``values`` put at the indices ``at`` (an index array or a slice) along ``axis`` (-1 or 0) of an
    array of ``size`` there, ``fill`` elsewhere."""
    if axis == 0:
        out = _filled((size,) + values.shape[1:], fill, values.dtype)
        out[at] = values
    else:
        out = _filled(values.shape[:-1] + (size,), fill, values.dtype)
        out[..., at] = values
    return out


def _columns(cols: np.ndarray, a: np.ndarray, npix: int):
    """A batch's per-pixel array ``a`` (..., m) over the columns ``cols`` (m,) of the film, as it travels:
    its non-zero columns (:class:`Columns`) where they are fewer than :data:`SPARSE_SHARE` of the film's
    ``npix`` pixels, else the whole array (zeros elsewhere)."""
    nz = np.flatnonzero(a if a.ndim == 1 else a.any(axis=0))
    if len(nz) < SPARSE_SHARE * npix:
        return Columns(cols[nz], a[..., nz])
    out = np.zeros(a.shape[:-1] + (npix,))
    out[..., cols] = a
    return out


class _Replicates:
    """The replicate sums of one group of components: per pixel the sum over replicates of Y(m_r)^2
    (the sum of Y(m_r) is the image's own luminance times the count: every replicate has an equal
    share of the normaliser), the sums of the replicates' image means and of their squares, and their
    count: a number where every replicate covers the whole image, or per pixel (``pixel_count``) where
    batches cover part of it (a backward batch of fewer samples than pixels: one sample per pixel it
    covers, each a replicate of that pixel)."""

    def __init__(self, n: int):
        self.sq = np.zeros(n)  # over the film's layout (Film)
        self.mean_sum = 0.0
        self.mean_sq = 0.0
        self.count = 0
        self.pixel_count: np.ndarray | None = None

    def counts(self):
        """Replicates per pixel of the film's layout: the count, plus ``pixel_count`` where batches cover
        part of the image."""
        return self.count if self.pixel_count is None else self.pixel_count + self.count

    def merge(self, data: tuple, place):
        """Add a batch's replicate sums; ``place(pixels)``: their positions in the film's layout."""
        sq, mean_sum, mean_sq, count, covered = data
        _add(self.sq, sq, place)
        self.mean_sum += mean_sum
        self.mean_sq += mean_sq
        self.count += count
        if covered is not None:
            if self.pixel_count is None:
                self.pixel_count = np.zeros(len(self.sq), np.int32)
            self.pixel_count[place(covered)] += 1


def batch_arrays(components: list[str], npix: int, splats: Splats, replicates: int, normalisers: dict) -> tuple:
    """A batch's film as it travels (:meth:`Film.merge_arrays` adds it), built over the pixels it touches
    only, so that a batch costs memory by its samples, not by the retina's pixels: per component its
    RGB sums and the sums over replicates of each replicate's Y squared, its normaliser, and the
    group's replicate sums. ``normalisers[c]`` is the batch's normaliser total of component c (every
    replicate an equal share), or the flat pixels (k,) that the batch sampled once each (a batch that
    covers part of the image: then ``replicates`` is 1, and each sampled pixel's count grows by one).
    The numbers are those of adding each splat to a whole-image array, bit for bit: the sums run over
    the same values in the same order."""
    gathered = {k: splats.gather(k) for k in components}
    covered = next((v for v in normalisers.values() if isinstance(v, np.ndarray)), None)
    parts = [g[0] for g in gathered.values()] + ([covered] if covered is not None else [])
    cols = np.unique(np.concatenate(parts)) if parts else np.zeros(0, np.int64)
    m = len(cols)
    sums, norms, sq_c, total = [], [], [], None
    for name in components:
        pixels, rep, values = gathered[name]
        local = np.searchsorted(cols, pixels)
        s = np.zeros((3, m))
        if len(pixels):
            for c in range(3):
                s[c] = np.bincount(local, weights=values[c], minlength=m)
        norm = normalisers.get(name, 0)
        per_replicate = 1.0 if isinstance(norm, np.ndarray) else max(norm, 1) / replicates
        images = replicate_images(local, rep, values, replicates, m, per_replicate)
        sums.append(_columns(cols, s, npix))
        norms.append(norm if isinstance(norm, np.ndarray) else int(norm))
        sq_c.append(_columns(cols, (images * images).sum(axis=0), npix))
        total = images if total is None else total + images
    if total is None:
        total = np.zeros((replicates, m))
    means = total.sum(axis=1) / npix
    group = (_columns(cols, (total * total).sum(axis=0), npix), float(means.sum()), float((means * means).sum()),
             0 if covered is not None else replicates, covered)
    return components, sums, norms, sq_c, {"": group}


class Film:
    """Sums of one or more batches.

    Parameters
    ----------
    width, height : retina pixels.
    components : {name: normaliser kind} ("samples per pixel" or "particles", free text for the report).
    groups : {component: group}: components whose replicates are independent of the others' (the
        channels of the hybrid method, each traced by its own method on its own random streams) form
        groups; each group keeps its own replicate sums, and the variances of independent groups add.
        By default every component is in one group "".

    A component's normaliser is a number (particles emitted, or samples through every pixel) or, once
    batches that cover part of the image were merged, a count per pixel (samples through that pixel).

    The per-pixel arrays (``sums``, ``comp_rep_sq``, the groups' ``sq`` and ``pixel_count``, the
    normalisers counted per pixel) run over the film's layout: the pixels sampled so far, in the order
    first sampled, while the film is compact (``dense`` false; see the module's docstring), else every
    pixel. The results (:meth:`rgb`, :meth:`variance_y`, ...) are whole images either way;
    :meth:`make_dense` gives the arrays over every pixel.
    """

    def __init__(self, width: int, height: int, components: dict[str, str], groups: dict[str, str] | None = None):
        self.width, self.height = width, height
        self.kinds = dict(components)
        self.group_of = {name: (groups or {}).get(name, "") for name in components}
        # the compact layout: 1 + the position of each pixel sampled so far (0: not yet), the pixel at
        # each position, and how many positions are taken; _slot is None once the film is dense
        self._slot: np.ndarray | None = np.zeros(self.pixels, np.int32)
        self._pixel = np.zeros(0, np.int64)
        self._used = 0
        self.groups = {g: _Replicates(0) for g in dict.fromkeys(self.group_of.values())}
        self.sums = {name: np.zeros((3, 0)) for name in components}  # RGB, (3, layout)
        self.norm: dict[str, int | np.ndarray] = dict.fromkeys(components, 0)  # the normaliser's total
        self._floor = dict.fromkeys(components, 0)  # a per-pixel normaliser's value at pixels not yet sampled
        self.comp_rep_sq = {name: np.zeros(0) for name in components}  # per component, for its own error
        self._lum: dict[str, np.ndarray] = {}  # per component, its luminance (layout,) until the next merge

    @property
    def pixels(self) -> int:
        return self.width * self.height

    @property
    def dense(self) -> bool:
        """Whether the per-pixel arrays run over every pixel (else over the pixels sampled so far)."""
        return self._slot is None

    @property
    def replicates(self) -> int:
        """Replicates recorded, over every group (per pixel where batches cover part of the image: the
        fewest any pixel holds)."""
        return sum(self._fewest(g) for g in self.groups.values())

    @property
    def fewest_replicates(self) -> int:
        """The replicates of the group that has fewest (an error needs two in every group), per pixel where
        batches cover part of the image."""
        return min((self._fewest(g) for g in self.groups.values()), default=0)

    def _fewest(self, rep: _Replicates) -> int:
        if rep.pixel_count is None or self._size < self.pixels:  # pixels not yet sampled add none
            return rep.count
        return rep.count + int(rep.pixel_count.min())

    @property
    def partial_coverage(self) -> bool:
        """Whether some group's batches covered part of the image (its counts are per pixel)."""
        return any(g.pixel_count is not None for g in self.groups.values())

    def layout_sample_counts(self) -> tuple[np.ndarray, int] | None:
        """Where batches covered part of the image: per position of the layout (layout,) the fewest
        samples any group took through that pixel, and that number at the pixels outside the layout;
        else None (every pixel had the same)."""
        partial = [g for g in self.groups.values() if g.pixel_count is not None]
        if not partial:
            return None
        return np.minimum.reduce([self._live(g.counts()) for g in partial]), min(g.count for g in partial)

    def sample_counts(self) -> np.ndarray | None:
        """(H, W) the fewest samples any group took through each pixel where batches covered part of the
        image, else None (every pixel had the same)."""
        found = self.layout_sample_counts()
        return None if found is None else self.to_pixels(*found).reshape(self.height, self.width)

    def layout_pixels(self) -> np.ndarray:
        """(layout,) the flat pixel at each position of the layout."""
        return np.arange(self.pixels) if self._slot is None else self._pixel[:self._used]

    def count_summary(self, name: str) -> tuple[float, int, int]:
        """The mean, fewest and most of component ``name``'s normaliser over the pixels (per pixel where
        batches covered part of the image)."""
        n = self.norm[name]
        if not isinstance(n, np.ndarray):
            return float(n), int(n), int(n)
        return summarise_counts(self._live(n), self._floor[name], self.pixels)

    @property
    def rep_sq(self) -> np.ndarray:
        """Per pixel of the layout, the sums over replicates of Y(m_r)^2, over every group."""
        return sum((self._live(g.sq) for g in self.groups.values()), start=np.zeros(self._size)) \
            if len(self.groups) > 1 else self._live(next(iter(self.groups.values())).sq)

    # -- layout ------------------------------------------------------------------------------------
    @property
    def _size(self) -> int:
        """Positions of the layout in use."""
        return self.pixels if self._slot is None else self._used

    def _live(self, a: np.ndarray) -> np.ndarray:
        """The positions in use of a per-pixel array (its capacity beyond them holds the untouched value);
        a number as it is."""
        return a if self._slot is None or np.ndim(a) == 0 else a[..., :self._used]

    def to_pixels(self, values: np.ndarray, fill=0, axis: int = -1) -> np.ndarray:
        """(..., pixels) flat, from ``values`` (..., layout) over the layout's positions in use, ``fill``
        at pixels not yet sampled; with ``axis`` 0, (pixels, ...) from (layout, ...)."""
        if self._slot is None:
            return values
        return _placed(values, self.pixels, self._pixel[:self._used], fill, axis)

    def _each_array(self, remake):
        """Replace every per-pixel array ``a`` by ``remake(a, fill)``, ``fill`` being its value at pixels
        not yet sampled."""
        for k in self.sums:
            self.sums[k] = remake(self.sums[k], 0)
            self.comp_rep_sq[k] = remake(self.comp_rep_sq[k], 0)
            if isinstance(self.norm[k], np.ndarray):
                self.norm[k] = remake(self.norm[k], self._floor[k])
        for rep in self.groups.values():
            rep.sq = remake(rep.sq, 0)
            if rep.pixel_count is not None:
                rep.pixel_count = remake(rep.pixel_count, 0)

    def make_dense(self):
        """Put the per-pixel arrays over every pixel (no number changes)."""
        if self._slot is None:
            return
        used, at = self._used, self._pixel[:self._used]
        self._each_array(lambda a, fill: _placed(a[..., :used], self.pixels, at, fill))
        self._slot, self._pixel, self._used = None, np.zeros(0, np.int64), 0
        self._lum.clear()

    def _take_positions(self, pixels: np.ndarray):
        """Give the pixels not yet sampled among ``pixels`` positions in the layout (in the order given),
        growing its arrays by half; the film turns dense when they pass :data:`COMPACT_SHARE` of the
        retina."""
        if self._slot is None or len(pixels) == 0:
            return
        new = pixels[self._slot[pixels] == 0]
        if len(new) == 0:
            return
        _, first = np.unique(new, return_index=True)
        new = new[np.sort(first)]  # each once, in the order given
        used = self._used + len(new)
        if used > COMPACT_SHARE * self.pixels:
            self.make_dense()
            return
        capacity = len(self._pixel)
        if used > capacity:
            capacity = min(self.pixels, max(used, capacity + capacity // 2, 1024))

            def grow(a, fill):
                return _placed(a, capacity, slice(0, a.shape[-1]), fill)

            self._each_array(grow)
            self._pixel = grow(self._pixel, 0)
        self._pixel[self._used:used] = new
        self._slot[new] = np.arange(self._used + 1, used + 1, dtype=np.int32)
        self._used = used

    def _at(self, pixels: np.ndarray) -> np.ndarray:
        """The positions in the layout of ``pixels``, which have positions (:meth:`_take_positions`)."""
        return pixels if self._slot is None else self._slot[pixels] - 1

    @property
    def _capacity(self) -> int:
        return self.pixels if self._slot is None else len(self._pixel)

    # -- merging ---------------------------------------------------------------------------------
    def merge_arrays(self, data: tuple, prefix: str = "", group: str | None = None):
        """Add a batch's arrays (:func:`batch_arrays`); with ``prefix``,
        its components are this film's ``prefix + name``, and with ``group`` its replicate sums go to that
        group of this film (the hybrid method merges each channel's batch so)."""
        names, sums, norms, c_sq, groups = data
        self._lum.clear()
        arrays = [*sums, *c_sq, *(rep[0] for rep in groups.values())]
        if any(not isinstance(a, Columns) for a in arrays):  # a batch that lit most pixels travels whole
            self.make_dense()
        touched = [a.idx for a in arrays if isinstance(a, Columns)] + [n for n in norms if isinstance(n, np.ndarray)]
        touched += [rep[4] for rep in groups.values() if rep[4] is not None]
        if touched:
            self._take_positions(np.concatenate(touched))
        for i, k in enumerate(names):
            k = prefix + k
            _add(self.sums[k], sums[i], self._at)
            n = norms[i]
            if isinstance(n, np.ndarray):  # the pixels a batch sampled once each
                if not isinstance(self.norm[k], np.ndarray):
                    self._floor[k] = self.norm[k]
                    self.norm[k] = _filled((self._capacity,), self.norm[k], np.int32)
                self.norm[k][self._at(n)] += 1
            else:
                self.norm[k] += n
                self._floor[k] += n
            _add(self.comp_rep_sq[k], c_sq[i], self._at)
        for g, rep in groups.items():
            self.groups[g if group is None else group].merge(rep, self._at)

    # -- results ---------------------------------------------------------------------------------
    def finite(self) -> bool:
        """Whether every sum is finite (then so are the image and its variance: the normalisers are
        counts of at least one)."""
        arrays = [*self.sums.values(), *self.comp_rep_sq.values(), *(g.sq for g in self.groups.values())]
        return all(bool(np.isfinite(self._live(a)).all()) for a in arrays)

    def _divisor(self, name: str):
        """What a component's sums are divided by: its normaliser, at least 1 (per position of the layout
        where batches covered part of the image)."""
        n = self.norm[name]
        return np.maximum(self._live(n), 1) if isinstance(n, np.ndarray) else max(n, 1)

    def layout_rgb(self, group: str | None = None) -> np.ndarray:
        """(3, layout) mean apparent luminance, linear Rec.709, cd/m^2, at the layout's positions: the
        sum of the components (of ``group`` only, when given)."""
        out = np.zeros((3, self._size))
        for name in self.kinds:
            if group is None or self.group_of[name] == group:
                n = self._divisor(name)
                for c in range(3):  # a channel at a time: the same numbers as the whole (3, layout) at once
                    out[c] += self._live(self.sums[name])[c] / n
        return out

    def rgb(self, group: str | None = None) -> np.ndarray:
        """(H, W, 3) mean apparent luminance, linear Rec.709, cd/m^2: the sum of the components (of
        ``group`` only, when given)."""
        return np.ascontiguousarray(self.to_pixels(self.layout_rgb(group)).T).reshape(self.height, self.width, 3)

    def _y(self, names) -> np.ndarray:
        """(layout,) luminance of the sum of the components ``names`` (each component's kept until the
        next merge: the variances and the report ask for them again)."""
        y = np.zeros(self._size)
        for k in names:
            if k not in self._lum:
                # luminance3 of the divided sums, a channel at a time (the same terms)
                n, s = self._divisor(k), self._live(self.sums[k])
                lum = (s[0] / n) * Y_WEIGHTS[0]
                lum += (s[1] / n) * Y_WEIGHTS[1]
                lum += (s[2] / n) * Y_WEIGHTS[2]
                self._lum[k] = lum
            y += self._lum[k]
        return y

    def _variance(self, y: np.ndarray, sq: np.ndarray, r) -> np.ndarray:
        """Per position of the layout, the variance of the mean of r replicates whose mean is y and whose
        squares sum to sq (zero where fewer than two replicates exist)."""
        r = np.asarray(r)
        if r.ndim == 0 and r < 2:
            return np.zeros(self._size)
        rr = np.maximum(r, 2)
        var = sq / rr  # in place from here: a 4K image's temporaries are 66 MB each
        var -= y * y
        np.maximum(var, 0.0, out=var)
        var /= rr - 1
        if r.ndim:
            var[r < 2] = 0.0
        return var

    def layout_variance_y(self, group: str | None = None) -> np.ndarray:
        """(layout,) the sum of the groups' variances of the pixels' mean luminance (of ``group`` only)."""
        out = np.zeros(self._size)
        for g, rep in self.groups.items():
            if group is None or g == group:
                names = [k for k in self.kinds if self.group_of[k] == g]
                out = out + self._variance(self._y(names), self._live(rep.sq), self._live(rep.counts()))
        return out

    def variance_y(self, group: str | None = None) -> np.ndarray:
        """(H, W) variance of each pixel's mean luminance from the spread of the replicates, (cd/m^2)^2
        (zero where fewer than two replicates exist): the sum over the independent groups (of ``group``
        only, when given)."""
        return self.to_pixels(self.layout_variance_y(group)).reshape(self.height, self.width)

    def _mean_variances(self, group: str | None = None) -> list[tuple[float, str]]:
        """Per group (``group`` alone where given): the variance, (cd/m^2)^2, of its part of the image's
        mean luminance and what it is taken from (see :meth:`mean_standard_error_basis`)."""
        out = []
        for g, rep in self.groups.items():
            if group is not None and g != group:
                continue
            if rep.pixel_count is not None:
                var = float(self.layout_variance_y(g).sum()) / self.pixels**2
                out.append((var, "pixels" if int(np.max(self._live(rep.counts()), initial=0)) >= 2 else "none"))
                continue
            r = rep.count
            if r >= 2:
                mean = rep.mean_sum / r
                out.append((max(rep.mean_sq / r - mean * mean, 0.0) / (r - 1), "replicates"))
            else:
                out.append((0.0, "none"))
        return out

    def mean_standard_error(self, group: str | None = None) -> float:
        """Standard error (cd/m^2) of the image's mean luminance: from the spread of the replicates' image
        means where replicates cover the whole image, else from the pixels' own variances (the pixels
        of a camera method's image are independent estimates); 0 before two replicates exist. The
        groups' variances add."""
        return float(np.sqrt(sum(var for var, _ in self._mean_variances(group))))

    def mean_standard_error_basis(self, group: str | None = None) -> str:
        """What :meth:`mean_standard_error` is taken from, for the report: "replicates" (the spread of
        the whole-image replicates' means), "pixels" (the pixels' own variances, each from the samples
        of that pixel; pixels with fewer than two are left out, so that it is a lower bound where some
        are), or "none" (fewer than two replicates or samples: no error bar, the figure reads 0); the
        groups' bases joined by "+" where they differ."""
        return "+".join(dict.fromkeys(basis for _, basis in self._mean_variances(group))) or "none"

    def component_totals(self, name: str) -> tuple[float, float]:
        """One component's luminance, cd/m^2, and that luminance's variance, (cd/m^2)^2, each summed over
        the pixels."""
        rep = self.groups[self.group_of[name]]
        y = self._y([name])
        var = self._variance(y, self._live(self.comp_rep_sq[name]), self._live(rep.counts()))
        return float(y.sum()), float(var.sum())


class Splats:
    """What one batch adds to a film, collected bounce by bounce: per component, flat pixel indices
    (m,), replicate indices (m,) and RGB values (3, m) (not yet normalised)."""

    def __init__(self):
        self.parts: dict[str, list] = {}

    def add(self, component: str, pixels: np.ndarray, replicate: np.ndarray, values: np.ndarray):
        if len(pixels):
            self.parts.setdefault(component, []).append((pixels, replicate, values))

    def gather(self, component: str):
        parts = self.parts.get(component, [])
        if not parts:
            return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((3, 0))
        return (np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts]),
                np.concatenate([p[2] for p in parts], axis=1))


def replicate_images(pixels: np.ndarray, replicate: np.ndarray, values: np.ndarray, replicates: int, npix: int,
                     normaliser: float) -> np.ndarray:
    """(R, pixels) Y images of the replicates: the luminance of ``values`` (3, m) added at ``pixels``
    (m,) of replicate ``replicate`` (m,), divided by each replicate's ``normaliser``."""
    if len(pixels) == 0:
        return np.zeros((replicates, npix))
    y = luminance3(values) / normaliser
    return np.bincount(replicate * npix + pixels, weights=y, minlength=replicates * npix).reshape(replicates, npix)
