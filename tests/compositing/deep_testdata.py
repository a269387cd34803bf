"""Random deep images and OpenImageIO conversions for the deep-image tests.

The OpenImageIO side is built sample by sample with ``ImageBuf.set_deep_samples`` /
``set_deep_value`` (not with :mod:`compositing.deep_io`), so the comparisons do not rely on
the code under test to hand the data over.
"""

from __future__ import annotations

import itertools

import numpy as np
import OpenImageIO as oiio  # noqa: N813

from compositing.deep import DeepImage

CHANNELS = ("R", "G", "B", "A", "Z", "ZBack")


def random_deep(
    rng: np.random.Generator,
    shape: tuple[int, int],
    *,
    max_samples: int = 16,
    layout: str = "messy",
    opaque_at: float = 10.0,
) -> DeepImage:
    """A deep image of 0..max_samples samples per pixel, stored in random order.

    ``layout="messy"``: point samples (a third; ``zback == z``) and volume samples anywhere in
    [0, 14), overlapping each other; about one sample in eight has alpha 0 and one in eight
    alpha 1; one in ten repeats another sample's depths exactly (coincident samples).

    ``layout="oiio"``: the same ingredients (alpha below 0.95 or exactly 0 or 1) arranged
    where OpenImageIO 3.0 computes what the OpenEXR document defines (its known departures
    have tests of their own): point samples
    (alpha 0 to 1, coincident ones included) in [0, 4); non-opaque volume samples (alpha 0
    included, coincident ones included) overlapping each other in [4, 10); and in half the
    pixels an opaque volume sample starting in ``[opaque_at, opaque_at + 0.5)`` (≥ 10), 1 to 2
    long, overlapped by one non-opaque volume sample starting inside it. Points never fall
    inside a volume and an opaque piece never coincides with more than one other piece.

    Colour is premultiplied: ``rgb = alpha · straight``, straight in [0, 1]; for alpha 0 a small
    emission colour is kept.
    """
    h, w = shape
    oiio_layout = layout == "oiio"
    extra = rng.random((h, w)) < 0.5 if oiio_layout else np.zeros((h, w), bool)
    base = rng.integers(0, max_samples + 1 - 2 * extra, size=(h, w))
    counts = base + 2 * extra
    n = int(counts.sum())
    point = rng.random(n) < 1 / 3
    # OpenImageIO splits pieces again in float32: near alpha 1 that loses the optical depth
    # -log(1 - alpha) (relative error ulp/(1 - alpha)), so its layout keeps alpha <= 0.95 or = 1.
    alpha = rng.uniform(0.0, 0.95 if layout == "oiio" else 1.0, n)
    kind = rng.random(n)
    alpha[kind < 1 / 8] = 0.0
    alpha[kind > 7 / 8] = 1.0
    if oiio_layout:
        z = np.where(point, rng.uniform(0.0, 4.0, n), rng.uniform(4.0, 7.0, n))
        zb = np.where(point, z, z + rng.uniform(0.05, 3.0, n))
        alpha[~point & (alpha == 1.0)] = 0.5
    else:
        z = rng.uniform(0.0, 10.0, n)
        zb = np.where(point, z, z + rng.uniform(0.05, 4.0, n))
    straight = rng.uniform(0.0, 1.0, (n, 3))
    offsets = np.concatenate([[0], np.cumsum(counts.reshape(-1))])
    flat_extra = extra.reshape(-1)
    for p in range(h * w):
        lo, hi = offsets[p], offsets[p + 1]
        core_hi = hi - 2 * int(flat_extra[p])
        for s in lo + np.flatnonzero(rng.random(core_hi - lo) < 0.1):
            same = lo + np.flatnonzero(point[lo:core_hi] == point[s])
            src = rng.choice(same)
            z[s], zb[s] = z[src], zb[src]
        if flat_extra[p]:
            o, t = hi - 2, hi - 1
            point[o] = point[t] = False
            z[o] = opaque_at + rng.uniform(0.0, 0.5)
            zb[o] = z[o] + rng.uniform(1.0, 2.0)
            alpha[o] = 1.0
            z[t] = rng.uniform(z[o], zb[o])
            zb[t] = z[t] + rng.uniform(0.5, 2.0)
            alpha[t] = rng.uniform(0.0, 0.95)
    rgb = straight * alpha[:, None]
    rgb[alpha == 0] = 0.05 * straight[alpha == 0]
    # Samples of each pixel in random order (the extras are not always last).
    perm = np.concatenate([lo + rng.permutation(hi - lo) for lo, hi in itertools.pairwise(offsets)])
    perm = perm.astype(np.int64)
    rgba = np.concatenate([rgb, alpha[:, None]], axis=1)
    return DeepImage(
        counts, z[perm].astype(np.float32), zb[perm].astype(np.float32), rgba[perm].astype(np.float32)
    )


def to_imagebuf(image: DeepImage) -> oiio.ImageBuf:
    """A deep OpenImageIO ImageBuf with the same samples (channels R, G, B, A, Z, ZBack)."""
    h, w = image.shape
    spec = oiio.ImageSpec(w, h, len(CHANNELS), oiio.FLOAT)
    spec.channelnames = CHANNELS
    spec.deep = True
    buf = oiio.ImageBuf(spec)
    for y in range(h):
        for x in range(w):
            buf.set_deep_samples(x, y, 0, int(image.counts[y, x]))
    for y in range(h):
        for x in range(w):
            z, zb, rgba = image.pixel(y, x)
            for s in range(len(z)):
                values = (*rgba[s].tolist(), float(z[s]), float(zb[s]))
                for c, v in enumerate(values):
                    buf.set_deep_value(x, y, 0, c, s, v)
    return buf


def from_imagebuf(buf: oiio.ImageBuf) -> DeepImage:
    """The samples of a deep ImageBuf (channels found by name) as a DeepImage."""
    spec = buf.spec()
    names = list(spec.channelnames)
    chans = [names.index(k) for k in ("R", "G", "B", "A", "Z")]
    chans.append(next(i for i, n in enumerate(names) if n.lower() == "zback"))
    counts = np.array([[buf.deep_samples(x, y, 0) for x in range(spec.width)] for y in range(spec.height)])
    values = [
        [buf.deep_value(x, y, 0, c, s) for c in chans]
        for y in range(spec.height)
        for x in range(spec.width)
        for s in range(counts[y, x])
    ]
    v = np.array(values, np.float32).reshape(-1, 6)
    return DeepImage(counts, v[:, 4], v[:, 5], v[:, :4])


def to_deepdata(image: DeepImage) -> oiio.DeepData:
    """A DeepData with the same samples, filled sample by sample."""
    h, w = image.shape
    dd = oiio.DeepData()
    dd.init(h * w, len(CHANNELS), (oiio.FLOAT,) * len(CHANNELS), CHANNELS)
    for p in range(h * w):
        dd.set_samples(p, int(image.counts.reshape(-1)[p]))
    for p in range(h * w):
        z, zb, rgba = image.pixel(p // w, p % w)
        for s in range(len(z)):
            for c, v in enumerate((*rgba[s].tolist(), float(z[s]), float(zb[s]))):
                dd.set_deep_value(p, c, s, v)
    return dd


def deepdata_image(dd: oiio.DeepData, shape: tuple[int, int]) -> DeepImage:
    """The samples of a DeepData (channels in the order of :data:`CHANNELS`) as a DeepImage."""
    h, w = shape
    counts = np.array([dd.samples(p) for p in range(h * w)]).reshape(h, w)
    v = np.array(
        [[dd.deep_value(p, c, s) for c in range(6)] for p in range(h * w) for s in range(dd.samples(p))],
        np.float32,
    ).reshape(-1, 6)
    return DeepImage(counts, v[:, 4], v[:, 5], v[:, :4])


def oiio_tidy(image: DeepImage) -> DeepImage:
    """OpenImageIO's tidy of every pixel: the steps of ``DeepData::merge_deep_pixels``.

    Sort, split every sample at every sample's Z and ZBack (``DeepData.split``), sort again,
    merge coincident neighbours (``DeepData.merge_overlaps``).
    """
    dd = to_deepdata(image)
    for p in range(dd.pixels):
        dd.sort(p)
        s = 0
        while s < dd.samples(p):
            z, zb = dd.deep_value(p, 4, s), dd.deep_value(p, 5, s)
            dd.split(p, z)
            dd.split(p, zb)
            s += 1
        dd.sort(p)
        dd.merge_overlaps(p)
    return deepdata_image(dd, image.shape)


def flat_pixels(buf: oiio.ImageBuf) -> np.ndarray:
    """The RGBA channels of a flat ImageBuf as ``(H, W, 4)`` float32."""
    spec = buf.spec()
    names = list(spec.channelnames)
    px = np.asarray(buf.get_pixels(oiio.FLOAT)).reshape(spec.height, spec.width, spec.nchannels)
    return px[..., [names.index(k) for k in ("R", "G", "B", "A")]]


def one_pixel(samples: list[tuple[float, float, float, float, float, float]]) -> DeepImage:
    """A 1×1 image from ``(z, zback, r, g, b, a)`` rows."""
    s = np.array(samples, np.float64).reshape(-1, 6)
    return DeepImage(np.array([[len(s)]]), s[:, 0], s[:, 1], s[:, 2:])
