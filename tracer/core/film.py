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

Groups. Components traced independently of each other (the hybrid method's channels: each its own
method, its own random streams, its own replicates) form groups; each group keeps its own replicate
sums, and the image's variance is the sum of the groups' variances (independent estimates add).
"""

from __future__ import annotations

import numpy as np

from .units import luminance3

#: A batch's per-pixel array travels as its non-zero columns (:class:`Columns`) when they are fewer
#: than this share of the pixels.
SPARSE_SHARE = 0.25


class Columns:
    """The columns ``idx`` (m,) of a per-pixel array whose other columns are zero: ``values`` (..., m)."""

    __slots__ = ("idx", "values")

    def __init__(self, idx: np.ndarray, values: np.ndarray):
        self.idx, self.values = idx, values

    def __getstate__(self):
        return self.idx, self.values

    def __setstate__(self, state):
        self.idx, self.values = state


def _pack(a: np.ndarray):
    """A per-pixel array (pixels,) or (k, pixels) as it travels: its non-zero columns
    (:class:`Columns`) where they are fewer than :data:`SPARSE_SHARE` of the pixels, else whole."""
    idx = np.flatnonzero(a if a.ndim == 1 else a.any(axis=0))
    return Columns(idx, a[..., idx]) if len(idx) < SPARSE_SHARE * a.shape[-1] else a


def _add(total: np.ndarray, a) -> None:
    """``total += a`` for a dense array or :class:`Columns` (the same bits either way: x + 0 = x)."""
    if isinstance(a, Columns):
        total[..., a.idx] += a.values
    else:
        total += a


class _Replicates:
    """The replicate sums of one group of components: per pixel the sums over replicates of Y(m_r) and
    of its square, the sums of the replicates' image means and of their squares, and their count."""

    def __init__(self, n: int):
        self.sum = np.zeros(n)
        self.sq = np.zeros(n)
        self.mean_sum = 0.0
        self.mean_sq = 0.0
        self.count = 0

    def add(self, images: np.ndarray | None, replicates: int):
        """Add the (R, pixels) replicate images of one batch (None: nothing landed)."""
        if images is not None:
            self.sum += images.sum(axis=0)
            self.sq += (images * images).sum(axis=0)
            means = images.mean(axis=1)
            self.mean_sum += float(means.sum())
            self.mean_sq += float((means * means).sum())
        self.count += replicates

    def arrays(self) -> tuple:
        return _pack(self.sum), _pack(self.sq), self.mean_sum, self.mean_sq, self.count

    def merge(self, data: tuple):
        s, sq, mean_sum, mean_sq, count = data
        _add(self.sum, s)
        _add(self.sq, sq)
        self.mean_sum += mean_sum
        self.mean_sq += mean_sq
        self.count += count


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
    """

    def __init__(self, width: int, height: int, components: dict[str, str], groups: dict[str, str] | None = None):
        self.width, self.height = width, height
        n = width * height
        self.kinds = dict(components)
        self.group_of = {name: (groups or {}).get(name, "") for name in components}
        self.groups = {g: _Replicates(n) for g in dict.fromkeys(self.group_of.values())}
        self.sums = {name: np.zeros((3, n)) for name in components}  # RGB, (3, pixels)
        self.norm = dict.fromkeys(components, 0)  # the normaliser's total
        self.comp_rep_sum = {name: np.zeros(n) for name in components}  # per component, for its own error
        self.comp_rep_sq = {name: np.zeros(n) for name in components}

    @property
    def pixels(self) -> int:
        return self.width * self.height

    @property
    def replicates(self) -> int:
        """Replicates recorded, over every group."""
        return sum(g.count for g in self.groups.values())

    @property
    def fewest_replicates(self) -> int:
        """The replicates of the group that has fewest (an error needs two in every group)."""
        return min((g.count for g in self.groups.values()), default=0)

    @property
    def rep_sum(self) -> np.ndarray:
        """Per pixel, the sums over replicates of Y(m_r), over every group."""
        return sum((g.sum for g in self.groups.values()), start=np.zeros(self.pixels)) if len(self.groups) > 1 \
            else next(iter(self.groups.values())).sum

    @property
    def rep_sq(self) -> np.ndarray:
        """Per pixel, the sums over replicates of Y(m_r)^2, over every group."""
        return sum((g.sq for g in self.groups.values()), start=np.zeros(self.pixels)) if len(self.groups) > 1 \
            else next(iter(self.groups.values())).sq

    # -- filling (one batch) ---------------------------------------------------------------------
    def record_batch(self, splats: Splats, replicates: int, normalisers: dict[str, int], group: str = ""):
        """Add one batch of the components of ``group``: its ``splats``, made of ``replicates``
        replicates, with the batch's normaliser total of each component (every replicate has an equal
        share of it)."""
        total = None
        for name in self.kinds:
            if self.group_of[name] != group:
                continue
            pixels, rep, values = splats.gather(name)
            norm = normalisers.get(name, 0)
            if len(pixels):
                s = self.sums[name]
                for c in range(3):
                    s[c] += np.bincount(pixels, weights=values[c], minlength=self.pixels)
            images = replicate_images(pixels, rep, values, replicates, self.pixels, max(norm, 1) / replicates)
            self.comp_rep_sum[name] += images.sum(axis=0)
            self.comp_rep_sq[name] += (images * images).sum(axis=0)
            total = images if total is None else total + images
            self.norm[name] += int(norm)
        self.groups[group].add(total, replicates)

    # -- merging ---------------------------------------------------------------------------------
    def arrays(self) -> tuple:
        """Everything a batch contributes, as arrays and numbers (what workers send back); each
        per-pixel array whole or as its non-zero columns (:func:`_pack`)."""
        names = list(self.kinds)
        return (names, [_pack(self.sums[k]) for k in names], [self.norm[k] for k in names],
                [_pack(self.comp_rep_sum[k]) for k in names], [_pack(self.comp_rep_sq[k]) for k in names],
                {g: r.arrays() for g, r in self.groups.items()})

    def merge_arrays(self, data: tuple, prefix: str = "", group: str | None = None):
        """Add another film's :meth:`arrays`; with ``prefix``, its components are this film's
        ``prefix + name``, and with ``group`` its replicate sums go to that group of this film (the
        hybrid method merges each channel's own film so)."""
        names, sums, norms, c_sum, c_sq, groups = data
        for i, k in enumerate(names):
            k = prefix + k
            _add(self.sums[k], sums[i])
            self.norm[k] += norms[i]
            _add(self.comp_rep_sum[k], c_sum[i])
            _add(self.comp_rep_sq[k], c_sq[i])
        for g, rep in groups.items():
            self.groups[g if group is None else group].merge(rep)

    def merge(self, other: Film):
        self.merge_arrays(other.arrays())

    # -- results ---------------------------------------------------------------------------------
    def component_rgb(self, name: str) -> np.ndarray:
        """(H, W, 3) one component's estimate, cd/m^2."""
        s = self.sums[name] / max(self.norm[name], 1)
        return np.ascontiguousarray(s.T).reshape(self.height, self.width, 3)

    def rgb(self, group: str | None = None) -> np.ndarray:
        """(H, W, 3) mean apparent luminance, linear Rec.709, cd/m^2: the sum of the components (of
        ``group`` only, when given)."""
        out = np.zeros((self.height, self.width, 3))
        for name in self.kinds:
            if group is None or self.group_of[name] == group:
                out += self.component_rgb(name)
        return out

    def _variance(self, s: np.ndarray, sq: np.ndarray, r: int) -> np.ndarray:
        if r < 2:
            return np.zeros((self.height, self.width))
        mean = s / r
        var = np.maximum(sq / r - mean * mean, 0.0) * r / (r - 1)
        return (var / r).reshape(self.height, self.width)

    def variance_y(self, group: str | None = None) -> np.ndarray:
        """(H, W) variance of each pixel's mean luminance from the spread of the replicates, (cd/m^2)^2
        (zeros before two replicates exist): the sum over the independent groups (of ``group`` only,
        when given)."""
        out = np.zeros((self.height, self.width))
        for g, rep in self.groups.items():
            if group is None or g == group:
                out = out + self._variance(rep.sum, rep.sq, rep.count)
        return out

    def mean_standard_error(self, group: str | None = None) -> float:
        """Standard error (cd/m^2) of the image's mean luminance, from the spread of the replicates'
        image means (0 before two replicates exist); the groups' variances add."""
        var = 0.0
        for g, rep in self.groups.items():
            r = rep.count
            if r >= 2 and (group is None or g == group):
                mean = rep.mean_sum / r
                var += max(rep.mean_sq / r - mean * mean, 0.0) / (r - 1)
        return float(np.sqrt(var))

    def component_variance_y(self, name: str) -> np.ndarray:
        return self._variance(self.comp_rep_sum[name], self.comp_rep_sq[name], self.groups[self.group_of[name]].count)


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
