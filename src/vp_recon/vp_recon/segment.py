"""Plant pixels of a flight's images, from the images alone (the renderer's masks are an oracle
only the ideal capture keeps): :func:`plant_mask` by excess green over soil, the colour key of the
rendered sky (:func:`vp_scene.render.foreground_mask`) over the blue screen (:func:`image_mask`
picks by the background), and for a plant of any colour over soil
:func:`flight_masks`: two segmentations, and a rule that picks one per flight:

``exg``
    Excess green (:func:`plant_mask`): the crop-segmentation index. It finds a
    green plant on soil well and nothing on a plant that is not green (a dried plant: every
    image registered, next to no point kept).
``background``
    The plant is what the background is not, from the image's own statistics
    (:func:`background_mask`): a Gaussian mixture of the background's colours (CIE Lab, from OpenCV's
    k-means) is fitted on pixels that are background for sure, and a pixel whose colour the mixture
    explains worse than all but ``BACKGROUND_QUANTILE`` of those samples (less a margin) is
    plant. The samples are the image's border band and, when the planning cloud's box is known
    (the prior), every pixel outside the box's projection, which is also background in the mask:
    the geometry of the prior says where the plant can be, the colours say which pixels of that
    region are not background. No plant colour is assumed: a brown, yellow or purple plant on
    soil, a green one on a black cloth.
``auto`` (the default)
    ``exg`` when the plant is green, else ``background`` (:func:`choose_method`): over the
    whole flight, the excess-green mask must hold at least :data:`EXG_SHARE` of the pixels the
    background model of the border band calls plant (the box left out of the decision: a camera
    close to the plant sees its box over most of the frame, and what is left outside may be one
    colour, a lens's black margin). A green plant's ExG mask is most of them (the background
    model also flags markers, stones, a pot); a plant that is not green leaves ExG almost empty.

Each one's agreement with the oracle and the rule's margins: docs/results.md "Plant masks".
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vp_scene.render import foreground_mask

__all__ = ["EXG_THRESHOLD", "MASK_METHODS", "EXG_SHARE", "BACKGROUND_QUANTILE", "BACKGROUND_MARGIN", "MaskChoice",
           "excess_green", "plant_mask", "image_mask", "background_mask", "box_hull", "choose_method", "flight_masks"]

#: Excess-green threshold of :func:`plant_mask`, with a 3x3 opening and closing: the value that
#: suits both the procedural plant and Corn50 on the soil texture (higher ones drop Corn50's
#: yellowish leaves). An Otsu threshold (on ExG, ExGR or CIVE) splits the soil's own spread of
#: straw strokes, not the plant from the soil.
EXG_THRESHOLD: float = 0.04


def excess_green(image: NDArray[np.uint8]) -> NDArray[np.float64]:
    """ExG = 2g - r - b on chromatic coordinates r = R / (R + G + B) etc. (Woebbecke et al. 1995;
    the crop-segmentation index Meyer & Neto 2008 compare ExGR and CIVE with), in [-1, 2].
    A black pixel (R + G + B = 0) has ExG 0."""
    x = np.asarray(image)[..., :3].astype(np.float64)
    s = x.sum(axis=-1)
    s = np.where(s > 0, s, 1.0)
    return (2.0 * x[..., 1] - x[..., 0] - x[..., 2]) / s


def plant_mask(image: NDArray[np.uint8], threshold: float = EXG_THRESHOLD) -> NDArray[np.bool_]:
    """Plant pixels of an RGB image of plants on soil, from the image alone: ExG > ``threshold``
    (:func:`excess_green`), then a 3x3 morphological opening (specks of soil) and closing (holes
    in leaves; OpenCV's morphology)."""
    import cv2

    raw = (excess_green(image) > threshold).astype(np.uint8)
    k = np.ones((3, 3), np.uint8)
    return cv2.morphologyEx(cv2.morphologyEx(raw, cv2.MORPH_OPEN, k), cv2.MORPH_CLOSE, k) > 0


def image_mask(image: NDArray[np.uint8], ground: bool) -> NDArray[np.bool_]:
    """The plant mask a flight can compute from its image alone: :func:`plant_mask` over soil
    (``ground``), the colour key :func:`foreground_mask` over the blue sky."""
    return plant_mask(image) if ground else foreground_mask(image)


#: Segmentations a reconstruction can use (``ReconConfig.mask``, ``--mask``).
MASK_METHODS: tuple[str, ...] = ("auto", "exg", "background")
#: ``auto`` takes excess green when its masks hold at least this share of the pixels the
#: background model calls plant, over the flight.
EXG_SHARE: float = 0.55
#: The background model's threshold: the negative log-likelihood that this share of its own
#: samples stays under ...
BACKGROUND_QUANTILE: float = 0.99
#: ... plus this margin (nats).
BACKGROUND_MARGIN: float = 2.0
#: Mixture components of the background model.
BACKGROUND_COMPONENTS: int = 5
#: The background model's mask is made on the image resized to at most this many pixels across
#: (the mask is resized back): full size for a camera's usual images; a thin organ (a silique a
#: few pixels wide) blends into the background at a third of it.
WORK_WIDTH: int = 2048
#: ``auto`` decides on the background model of the images resized to this width (pixel counts
#: hardly depend on it, and a green plant's flight then pays little for the check).
DECIDE_WIDTH: int = 640
#: Width of the border band the samples come from without a prior, as a share of the shorter side.
BORDER: float = 0.04
#: A cluster of fewer than this share of the samples is not background: a plant that reaches the
#: border (a stalk through the top and bottom of a side view) is a small cluster of the band.
MIN_SHARE: float = 0.05
#: Samples the mixture is fitted on (a random subset, seeded).
MAX_SAMPLES: int = 6000


@dataclass
class MaskChoice:
    """What :func:`flight_masks` did: the method used (``exg`` or ``background`` for ``auto``),
    the pixels each candidate method called plant over the flight, and why."""

    method: str
    asked: str
    exg_pixels: int = 0
    background_pixels: int = 0
    reason: str = ""
    box: bool = False

    def to_dict(self) -> dict:
        return {"method": self.method, "asked": self.asked, "exg_pixels": self.exg_pixels,
                "background_pixels": self.background_pixels, "prior_box": self.box, "reason": self.reason}


def _lab(image: NDArray[np.uint8]) -> NDArray[np.float64]:
    import cv2

    return cv2.cvtColor(np.ascontiguousarray(image[..., :3], dtype=np.uint8), cv2.COLOR_RGB2LAB).astype(np.float64)


def _border(h: int, w: int) -> NDArray[np.bool_]:
    b = max(2, int(round(BORDER * min(h, w))))
    m = np.zeros((h, w), bool)
    m[:b], m[-b:], m[:, :b], m[:, -b:] = True, True, True, True
    return m


def _gmm_nll(samples: NDArray[np.float64], X: NDArray[np.float64], k: int, seed: int
             ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Negative log-likelihood of X (M, 3) and of the samples under a k-component Gaussian
    mixture of the samples: OpenCV's k-means clusters, each a Gaussian of its members' mean and
    covariance, weighted by its share (a hard-assignment EM step; OpenCV 5's wheel has no ``ml``
    module's EM and scikit-learn is not a dependency). The covariances get 4 Lab units^2 of
    noise so that a flat background, a cloth or a blue screen, is not a point mass."""
    import cv2

    k = int(min(k, max(1, len(samples) // 50)))
    cv2.setRNGSeed(int(seed))
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 0.5)
    _, labels, _ = cv2.kmeans(samples.astype(np.float32), k, None, crit, 2, cv2.KMEANS_PP_CENTERS)
    labels = labels.reshape(-1)
    terms_x, terms_s = [], []
    keep = np.bincount(labels, minlength=k) >= max(4, MIN_SHARE * len(samples))
    for j in np.flatnonzero(keep):
        members = samples[labels == j]
        mu = members.mean(axis=0)
        cov = np.cov(members.T) + 4.0 * np.eye(3)
        inv, logdet = np.linalg.inv(cov), np.linalg.slogdet(cov)[1]
        const = np.log(len(members) / len(samples)) - 0.5 * (logdet + 3 * np.log(2 * np.pi))
        for Y, terms in ((X, terms_x), (samples, terms_s)):
            d = Y - mu
            terms.append(const - 0.5 * np.einsum("ni,ij,nj->n", d, inv, d))
    own = -np.logaddexp.reduce(np.stack(terms_s), axis=0)
    return -np.logaddexp.reduce(np.stack(terms_x), axis=0), own[np.isin(labels, np.flatnonzero(keep))]


def background_mask(image: NDArray[np.uint8], outside: Optional[NDArray[np.bool_]] = None,
                    seed: int = 0, width: int = WORK_WIDTH) -> NDArray[np.bool_]:
    """Plant pixels (H, W) of an RGB image as what its background's colours do not explain
    (module docstring). The samples are the border band and ``outside``: (H, W) True where the
    pixel is background for sure (outside the prior's box), which is also background in the
    result (None: the border band alone). ``width``: the mask is made at most this many pixels
    across."""
    import cv2

    h, w = image.shape[:2]
    s = min(1.0, width / float(w))
    small = np.asarray(image[..., :3], np.uint8)
    if s < 1.0:
        small = cv2.resize(small, (max(8, int(round(w * s))), max(8, int(round(h * s)))), interpolation=cv2.INTER_AREA)
    hh, ww = small.shape[:2]
    out_small = None
    if outside is not None:
        out_small = cv2.resize(outside.astype(np.uint8), (ww, hh), interpolation=cv2.INTER_NEAREST) > 0
    region = _border(hh, ww)
    if out_small is not None:
        region = region | out_small
    lab = _lab(small).reshape(-1, 3)
    idx = np.flatnonzero(region.reshape(-1))
    rng = np.random.default_rng(seed)
    if len(idx) > MAX_SAMPLES:
        idx = rng.choice(idx, MAX_SAMPLES, replace=False)
    nll, own = _gmm_nll(lab[idx], lab, BACKGROUND_COMPONENTS, seed)
    raw = (nll > np.quantile(own, BACKGROUND_QUANTILE) + BACKGROUND_MARGIN).reshape(hh, ww)
    if out_small is not None:
        raw &= ~out_small
    k = np.ones((3, 3), np.uint8)
    m = cv2.morphologyEx(cv2.morphologyEx(raw.astype(np.uint8), cv2.MORPH_OPEN, k), cv2.MORPH_CLOSE, k)
    if (hh, ww) != (h, w):
        m = cv2.resize(m, (w, h), interpolation=cv2.INTER_NEAREST)
    return m > 0


def box_hull(box: ArrayLike, camera: ArrayLike, K: ArrayLike, size: tuple[int, int],
             grow: int = 0) -> Optional[NDArray[np.bool_]]:
    """(H, W) True inside the projection of the box ``[lo, hi]`` (2, 3) into the image of
    ``camera`` [c, v] with intrinsics K (``size`` = (W, H)): the convex hull of its 8 corners,
    grown by ``grow`` pixels. None when a corner lies behind the camera (the box surrounds it:
    no pixel can be ruled out)."""
    import cv2

    from vp_scene.camera import project_with

    lo, hi = np.asarray(box, dtype=np.float64).reshape(2, 3)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    w, h = int(size[0]), int(size[1])
    uv, _ = project_with(corners, camera, K, 10 ** 7, 10 ** 7, min_depth=1e-6)  # the frame's bounds not applied
    if not np.all(np.isfinite(uv)):
        return None
    m = np.zeros((h, w), np.uint8)
    hull = cv2.convexHull(np.round(uv).astype(np.int64).clip(-4 * max(w, h), 5 * max(w, h)).astype(np.int32))
    cv2.fillConvexPoly(m, hull, 1)
    if grow > 0:
        m = cv2.dilate(m, np.ones((2 * grow + 1, 2 * grow + 1), np.uint8))
    return m > 0


def choose_method(exg_pixels: int, background_pixels: int) -> tuple[str, str]:
    """``auto``'s choice (module docstring) from the pixels each method called plant over a
    flight: (method, reason)."""
    share = exg_pixels / max(background_pixels, 1)
    if share >= EXG_SHARE:
        return "exg", f"excess green holds {share:.2f} of the background model's plant pixels (>= {EXG_SHARE:g})"
    return "background", f"excess green holds {share:.2f} of the background model's plant pixels (< {EXG_SHARE:g}): " \
                         "the plant is not green"


def flight_masks(images: Sequence[NDArray[np.uint8]], method: str = "auto", cameras: Optional[ArrayLike] = None,
                 K: Optional[ArrayLike] = None, box: Optional[ArrayLike] = None
                 ) -> tuple[list, MaskChoice]:
    """The plant masks of a flight's images by ``method`` (:data:`MASK_METHODS`), and what was
    chosen. With ``box`` (the prior's box, (2, 3)), ``cameras`` (N, 6, the reported poses) and
    ``K``, the background model learns from outside the box's projection (grown by 2 % of the
    image width for the poses' error) and keeps nothing there."""
    if method not in MASK_METHODS:
        raise ValueError(f"mask must be one of {', '.join(MASK_METHODS)}, got {method!r}")
    choice = MaskChoice(method=method, asked=method, box=box is not None)
    exg = [plant_mask(im) for im in images] if method in ("auto", "exg") else None
    if method == "exg":
        choice.exg_pixels = int(sum(int(m.sum()) for m in exg))
        return exg, choice
    outside: list = [None] * len(images)
    if box is not None and cameras is not None and K is not None:
        cams = np.asarray(cameras, dtype=np.float64).reshape(len(images), -1)  # [c, v] or poses (roll kept)
        for i, (im, cam) in enumerate(zip(images, cams)):
            h, w = im.shape[:2]
            hull = box_hull(box, cam, K, (w, h), grow=max(2, int(0.02 * w)))
            outside[i] = None if hull is None else ~hull
    if method == "auto":  # decided on the border's model at DECIDE_WIDTH; the chosen masks made at full size
        small = [background_mask(im, None, seed=i, width=DECIDE_WIDTH) for i, im in enumerate(images)]
        choice.exg_pixels = int(sum(int(m.sum()) for m in exg))
        choice.background_pixels = int(sum(int(m.sum()) for m in small))
        choice.method, choice.reason = choose_method(choice.exg_pixels, choice.background_pixels)
        if choice.method == "exg":
            return exg, choice
    bg = [background_mask(im, out, seed=i) for i, (im, out) in enumerate(zip(images, outside))]
    if method == "background":
        choice.background_pixels = int(sum(int(m.sum()) for m in bg))
    return bg, choice
