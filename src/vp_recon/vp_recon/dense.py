"""CPU dense stereo: a stand-in for COLMAP's PatchMatch stereo (which needs CUDA).

For overlapping camera pairs (each camera with the ``neighbours`` others it shares the most
verified SIFT matches with, as COLMAP's PatchMatch picks its source images; without matches, its
nearest others by the angle between the rays from the scene centre to the cameras), with the
known relative pose

    X_j = R X_i + T,   R = R_j R_i^T,   T = t_j - R t_i      (X = R_cw X_w + t per camera)

the pair is rectified (Bouguet's algorithm, ``cv2.stereoRectify``), matched with semi-global
matching (Hirschmüller, "Stereo Processing by Semiglobal Matching and Mutual Information",
TPAMI 2008; ``cv2.StereoSGBM``), and valid disparities d on foreground pixels are lifted to 3D
with the reprojection matrix Q: (X, Y, Z, W)^T = Q (u, v, d, 1)^T (``cv2.reprojectImageTo3D``),
then rotated back (X_i = R_1^T X_rect) and moved to the world (X_w = R_i^T (X_i - t_i)).
Vertical pairs are matched on transposed images. The disparity search range comes from the
guide points (the sparse cloud) as COLMAP's depth ranges do: the 1st-99th percentile of their
depths in the reference view, stretched by 25%.

The fused cloud is cleaned with image-only tests:

* crop to an axis-aligned box (the scene's bounding box plus a margin) - far-off blunders of
  wide or oblique pairs,
* silhouette consistency (visual hull, Laurentini 1994): a point that projects inside a view
  onto (dilated) background in any view is dropped,
* optional voxel-grid downsampling (one point, the mean, per occupied voxel).

The renderer's depth buffer is never used. If ``pycolmap.has_cuda`` the caller may prefer
COLMAP's PatchMatch; this module is the CPU path.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional, Sequence

import cv2
import numpy as np
from numpy.typing import NDArray

from vp_scene.camera import check_poses, project_with, world_to_camera

__all__ = ["DenseResult", "neighbour_pairs", "overlap_pairs", "dense_reconstruct", "scaled_views", "voxel_downsample",
           "silhouette_filter", "crop_to_box"]


@dataclass
class DenseResult:
    """Fused dense cloud: points (M, 3) world, colors (M, 3) uint8, the (reference, other) pairs
    that produced points, raw point count, and raw points per pair (same order as ``pairs``)."""

    points: NDArray[np.float64]
    colors: NDArray[np.uint8]
    pairs: list[tuple[int, int]]
    raw_points: int
    pair_points: list[int] = field(default_factory=list)


def neighbour_pairs(cameras: NDArray[np.float64], center: NDArray[np.float64], neighbours: int = 2,
                    max_angle: float = np.deg2rad(75.0), min_angle: float = np.deg2rad(2.0)) -> list[tuple[int, int]]:
    """Unique pairs (i, j), i < j: each camera with its ``neighbours`` nearest others by angle.

    The angle between cameras i, j is acos(a_i . a_j) with a = (c - center) / |c - center|;
    pairs outside [min_angle, max_angle] are skipped (no baseline / nothing in common).
    """
    cams = check_poses(cameras)
    a = cams[:, :3] - np.asarray(center, dtype=np.float64)
    n = np.linalg.norm(a, axis=1, keepdims=True)
    a = a / np.where(n > 0, n, 1.0)
    ang = np.arccos(np.clip(a @ a.T, -1.0, 1.0))
    np.fill_diagonal(ang, np.inf)
    pairs = set()
    for i in range(len(cams)):
        for j in np.argsort(ang[i])[:neighbours]:
            if min_angle <= ang[i, j] <= max_angle:
                pairs.add((min(i, int(j)), max(i, int(j))))
    return sorted(pairs)


def overlap_pairs(pair_inliers: dict, num_cameras: int, neighbours: int = 2, min_inliers: int = 15
                  ) -> list[tuple[int, int]]:
    """Unique pairs (i, j), i < j: each camera with the ``neighbours`` others it shares the most
    verified matches with (at least ``min_inliers``, COLMAP's minimum for a two-view geometry).

    This is how COLMAP's PatchMatch picks its source images (``mvs::Model``'s
    ``GetMaxOverlappingImages``: the images sharing the most sparse points): by what the images
    have in common, not by where the cameras stand.
    """
    pairs = set()
    for i in range(num_cameras):
        cand = [(n, j) for (a, b), n in pair_inliers.items() if n >= min_inliers and i in (a, b)
                for j in ((b if a == i else a),)]
        for _, j in sorted(cand, reverse=True)[:neighbours]:
            pairs.add((min(i, j), max(i, j)))
    return sorted(pairs)


def crop_to_box(points: NDArray[np.float64], lo: NDArray[np.float64], hi: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Mask of points inside the axis-aligned box [lo, hi]."""
    return np.all((points >= lo) & (points <= hi), axis=1)


def silhouette_filter(points: NDArray[np.float64], cameras: NDArray[np.float64], K: NDArray[np.float64],
                      masks: Sequence[NDArray[np.bool_]], dilate: int = 3) -> NDArray[np.bool_]:
    """Keep points that project onto (dilated) foreground in every view that sees them in-frame."""
    keep = np.ones(len(points), dtype=bool)
    kernel = np.ones((2 * dilate + 1, 2 * dilate + 1), np.uint8)
    for camera, m in zip(np.asarray(cameras, dtype=np.float64), masks):
        fg = cv2.dilate(np.asarray(m, np.uint8), kernel) > 0
        h, w = fg.shape
        uv, inside = project_with(points, camera, K, w, h, min_depth=1e-6)
        u, v = np.rint(uv[inside]).astype(np.int64).T
        bad = np.zeros(len(points), dtype=bool)
        bad[inside] = ~fg[v, u]
        keep &= ~bad
    return keep


def voxel_downsample(points: NDArray[np.float64], colors: NDArray[np.uint8], voxel: float
                     ) -> tuple[NDArray[np.float64], NDArray[np.uint8]]:
    """Mean point and colour per occupied voxel of edge ``voxel`` (no-op for voxel <= 0)."""
    if voxel <= 0 or len(points) == 0:
        return points, colors
    keys = np.floor(points / voxel).astype(np.int64)
    _, inv, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    inv = inv.reshape(-1)
    sums = np.zeros((len(counts), 3))
    np.add.at(sums, inv, points)
    csum = np.zeros((len(counts), 3))
    np.add.at(csum, inv, colors.astype(np.float64))
    return sums / counts[:, None], np.clip(csum / counts[:, None] + 0.5, 0, 255).astype(np.uint8)


_EMPTY = (np.zeros((0, 3)), np.zeros((0, 3), np.uint8))
#: grey level of the sky colour (pads images outside the frame).
_SKY_GREY = int(cv2.cvtColor(np.array([[[0, 0, 255]]], np.uint8), cv2.COLOR_RGB2GRAY)[0, 0])


def _columns(g: NDArray[np.uint8], lo: int, hi: int) -> NDArray[np.uint8]:
    """Columns lo..hi-1 of a grey image, padded with the sky grey outside the image."""
    out = np.full((g.shape[0], hi - lo), _SKY_GREY, np.uint8)
    a, b = max(lo, 0), min(hi, g.shape[1])
    if b > a:
        out[:, a - lo:b - lo] = g[:, a:b]
    return out


def _frame(mask_i: NDArray[np.bool_], mask_j: NDArray[np.bool_], K: NDArray, D: NDArray, R1: NDArray,
           R2: NDArray, P1: NDArray, P2: NDArray, Q: NDArray, margin: int, max_side: int
           ) -> Optional[tuple[NDArray, NDArray, NDArray, tuple[int, int]]]:
    """Frame the rectified pair on the foreground: (P1, P2, Q, (width, height)), or None.

    Rectifying a strongly rotated pair into an image of the original size (alpha = -1 keeps
    the principal point's neighbourhood) can put the plant outside it. Both principal points
    are shifted by the same offset, which leaves every disparity unchanged, so that the
    rectified foreground of both views (plus ``margin``) starts at (0, 0); the output is sized
    to hold it (at most ``max_side`` pixels a side).
    """
    corners = []
    for m, Rr, Pr in ((mask_i, R1, P1), (mask_j, R2, P2)):
        ys, xs = np.nonzero(m[::4, ::4])
        if len(xs) == 0:
            return None
        pts = np.stack([xs * 4.0, ys * 4.0], axis=1).reshape(-1, 1, 2)
        corners.append(cv2.undistortPoints(pts, K, D, R=Rr, P=Pr).reshape(-1, 2))
    allc = np.concatenate(corners)
    allc = allc[np.all(np.isfinite(allc), axis=1)]
    if len(allc) == 0:
        return None
    lo = np.floor(allc.min(axis=0)) - margin
    hi = np.ceil(allc.max(axis=0)) + margin
    size = np.minimum(hi - lo, max_side).astype(int)
    P1, P2, Q = P1.copy(), P2.copy(), Q.copy()
    for P in (P1, P2):
        P[0, 2] -= lo[0]
        P[1, 2] -= lo[1]
    Q[0, 3], Q[1, 3] = -P1[0, 2], -P1[1, 2]
    return P1, P2, Q, (int(size[0]), int(size[1]))


def _sgm_cost(rows: int, cols: int, num: int) -> int:
    """SGM's work on a window of ``rows`` x ``cols`` reference pixels searching ``num`` disparities
    (its input is ``num`` columns wider: :func:`_pair_points`), in pixel-disparities."""
    return rows * (cols + num) * num


def _pair_points(img_i: NDArray[np.uint8], img_j: NDArray[np.uint8], mask_i: NDArray[np.bool_],
                 mask_j: NDArray[np.bool_], Ri: NDArray, ti: NDArray, Rj: NDArray, tj: NDArray, K: NDArray,
                 guide: NDArray, block: int, max_disparities: int,
                 max_cost: Optional[float] = None) -> tuple[NDArray[np.float64], NDArray[np.uint8]]:
    """World points and colours of one rectified pair (reference view i); empty when unusable.

    The rectified views are framed on both views' foreground (:func:`_frame`).

    ``guide`` (G, 3) world points bound the disparity search as COLMAP bounds PatchMatch depths:
    their depths in the rectified reference view, 1st-99th percentile, stretched by 25%, turned
    into disparities d = f |B| / Z (plus 4 px for rounding). SGBM then searches
    d' = d - s in [0, num) on column windows around the reference foreground: pixels left of
    ``num`` in an SGBM input have no valid disparity, so the window starts ``num`` columns early.

    ``max_cost``: SGM's work on the pair (:func:`_sgm_cost`) at most. A grazing pair, whose
    rectification stretches the plant over thousands of columns and a thousand disparities, would
    cost tens of times an ordinary one: it is
    matched on rectified views scaled by a = (max_cost / cost)^(1/3) instead (the rectified
    projections' first two rows times a: disparities, window and search range shrink by a, the
    depth step grows by 1 / a, Q follows), as ``scale`` does for every pair.
    """
    h, w = mask_i.shape
    R = Rj @ Ri.T
    T = (tj - R @ ti).reshape(3, 1)
    D = np.zeros(5)
    R1, R2, P1, P2, Q, _, _ = cv2.stereoRectify(K, D, K, D, (w, h), R, T, flags=cv2.CALIB_ZERO_DISPARITY, alpha=-1)
    vertical = abs(P2[1, 3]) > abs(P2[0, 3])
    base = P2[1, 3] if vertical else P2[0, 3]
    if base >= 0:                      # reference must be the left (upper) view: positive disparities
        return _EMPTY
    framed = _frame(mask_i, mask_j, K, D, R1, R2, P1, P2, Q, block + 16, 2 * max(w, h))
    if framed is None:
        return _EMPTY
    P1, P2, Q, (w, h) = framed
    Xr = (guide @ Ri.T + ti) @ R1.T    # guide points in the rectified reference frame
    Xr = Xr[Xr[:, 2] > 1e-6]
    if len(Xr) == 0:
        return _EMPTY
    # depth range as COLMAP's PatchMatch (mvs::Model::ComputeDepthRanges): the 1st-99th
    # percentile of the guide's depths, stretched by 25%; CALIB_ZERO_DISPARITY: d = f |B| / Z
    z_lo, z_hi = np.percentile(Xr[:, 2], [1, 99]) if len(Xr) >= 20 else (Xr[:, 2].min(), Xr[:, 2].max())

    def search(base: float) -> tuple[int, int]:
        lo_d, hi_d = -base / (1.25 * z_hi), -base / max(0.75 * z_lo, 1e-6)
        pad = 4
        shift = int(np.floor(lo_d - pad))
        num = int(np.ceil((hi_d + pad - shift) / 16.0)) * 16
        return shift, int(np.clip(num, 16, max_disparities))

    shift, num = search(base)
    cost = _sgm_cost(*((w, h) if vertical else (h, w)), num)   # the whole framed view: an upper bound
    if max_cost is not None and cost > max_cost:
        a = (max_cost / cost) ** (1.0 / 3.0)
        P1, P2, Q = P1.copy(), P2.copy(), Q.copy()
        P1[:2] *= a
        P2[:2] *= a
        Q[0, 3], Q[1, 3], Q[2, 3] = -P1[0, 2], -P1[1, 2], Q[2, 3] * a
        w, h = max(16, int(np.ceil(w * a))), max(16, int(np.ceil(h * a)))
        base *= a
        shift, num = search(base)
    m1x, m1y = cv2.initUndistortRectifyMap(K, D, R1, P1, (w, h), cv2.CV_32FC1)
    m2x, m2y = cv2.initUndistortRectifyMap(K, D, R2, P2, (w, h), cv2.CV_32FC1)
    r1 = cv2.remap(img_i, m1x, m1y, cv2.INTER_LINEAR, borderValue=(0, 0, 255))
    r2 = cv2.remap(img_j, m2x, m2y, cv2.INTER_LINEAR, borderValue=(0, 0, 255))
    rm = cv2.remap(mask_i.astype(np.uint8), m1x, m1y, cv2.INTER_NEAREST, borderValue=0) > 0
    if not rm.any():
        return _EMPTY
    g1 = cv2.cvtColor(r1, cv2.COLOR_RGB2GRAY)
    g2 = cv2.cvtColor(r2, cv2.COLOR_RGB2GRAY)
    rm_t = rm.T if vertical else rm
    if vertical:
        g1, g2 = g1.T.copy(), g2.T.copy()
    # window: rows and columns holding reference foreground (SGM cost ~ rows x cols x num)
    rows = np.flatnonzero(rm_t.any(axis=1))
    cols = np.flatnonzero(rm_t.any(axis=0))
    r0, r1_ = max(rows[0] - block, 0), min(rows[-1] + block + 1, g1.shape[0])
    c0, c1 = cols[0] - block, cols[-1] + block + 1
    left = _columns(g1[r0:r1_], c0 - num, c1)
    right = _columns(g2[r0:r1_], c0 - num - shift, c1 - shift)   # right'(x) = right(x - shift)
    sgbm = cv2.StereoSGBM.create(minDisparity=0, numDisparities=num, blockSize=block,
                                 P1=8 * block * block, P2=32 * block * block, disp12MaxDiff=1,
                                 uniquenessRatio=10, speckleWindowSize=100, speckleRange=2,
                                 mode=cv2.STEREO_SGBM_MODE_SGBM_3WAY)
    dw = sgbm.compute(left, right)[:, num:].astype(np.float32) / 16.0
    disp_t = np.full(g1.shape, -1.0, np.float32)
    a, b = max(c0, 0), min(c1, g1.shape[1])
    disp_t[r0:r1_, a:b] = dw[:, a - c0:b - c0]
    valid_t = disp_t >= 0
    disp_t = disp_t + shift
    disp = disp_t.T if vertical else disp_t
    valid = rm & (valid_t.T if vertical else valid_t)
    if not valid.any():
        return _EMPTY
    xyz = cv2.reprojectImageTo3D(np.ascontiguousarray(disp), Q)[valid].astype(np.float64)
    ok = np.all(np.isfinite(xyz), axis=1)
    X_i = xyz[ok] @ R1                 # X_i = R1^T X_rect (row vectors)
    X_w = (X_i - ti) @ Ri              # X_w = R_i^T (X_i - t_i)
    return X_w, r1[valid][ok]


def scaled_views(images: Sequence[NDArray[np.uint8]], masks: Sequence[NDArray[np.bool_]], K: NDArray[np.float64],
                 scale: float) -> tuple[list[NDArray[np.uint8]], list[NDArray[np.bool_]], NDArray[np.float64]]:
    """The views resized by ``scale`` (area averaging; a mask pixel is foreground where more than
    half of its area was) and the calibration that goes with them.

    Pixel centres sit at integer coordinates (OpenCV), so a column u of the original lies at
    u' = s_x (u + 1/2) - 1/2 of the resized view, s_x = w' / w (w' = round(s w)); likewise rows:
    f'_x = s_x f_x, c'_x = s_x (c_x + 1/2) - 1/2.
    """
    h, w = np.asarray(images[0]).shape[:2]
    w2, h2 = max(16, int(round(scale * w))), max(16, int(round(scale * h)))
    sx, sy = w2 / w, h2 / h
    K2 = np.asarray(K, dtype=np.float64).copy()
    K2[0, 0], K2[0, 1], K2[0, 2] = sx * K2[0, 0], sx * K2[0, 1], sx * (K2[0, 2] + 0.5) - 0.5
    K2[1, 1], K2[1, 2] = sy * K2[1, 1], sy * (K2[1, 2] + 0.5) - 0.5
    imgs = [cv2.resize(np.asarray(im), (w2, h2), interpolation=cv2.INTER_AREA) for im in images]
    ms = [cv2.resize(np.asarray(m, np.float32), (w2, h2), interpolation=cv2.INTER_AREA) > 0.5 for m in masks]
    return imgs, ms, K2


def dense_reconstruct(images: Sequence[NDArray[np.uint8]], masks: Sequence[NDArray[np.bool_]],
                      cameras: NDArray[np.float64], K: NDArray[np.float64], box: NDArray[np.float64],
                      guide: Optional[NDArray[np.float64]] = None, center: Optional[NDArray[np.float64]] = None,
                      neighbours: int = 2, block: int = 5, voxel: float = 0.0,
                      silhouette: bool = True, pair_inliers: Optional[dict] = None, scale: float = 1.0,
                      pair_budget: bool = True) -> DenseResult:
    """Fused SGBM cloud of neighbouring pairs, cropped to ``box`` ((2, 3) = [lo, hi]), cleaned.

    Args:
        images, masks: N RGB uint8 views and their foreground masks.
        cameras: (N, 7) camera poses (roll kept) or (N, 6) [c, v]; K: 3x3 calibration (OpenCV pixel convention).
        box: (2, 3) crop box.
        guide: (G, 3) points bounding the depth (disparity) search, e.g. the sparse cloud (as
            COLMAP bounds PatchMatch depths with the sparse points); points outside ``box`` are
            ignored; fewer than 10 left: a 5 x 5 x 5 grid over ``box``.
        center: scene centre for the neighbour angles (default: the box centre).
        neighbours: stereo partners per camera; block: SGBM block size (odd).
        pair_inliers: verified SIFT matches per pair (i, j) from the sparse step: partners are
            then chosen by :func:`overlap_pairs` (as COLMAP's PatchMatch chooses its source
            images); a camera with no such partner falls back to :func:`neighbour_pairs`.
        voxel: voxel edge for downsampling, metres (0: none).
        silhouette: drop points that project onto background in some view.
        scale: the stereo pairs are matched on the views resized by this factor (0 < scale <= 1;
            :func:`scaled_views`): SGM's cost falls about as scale^3 (pixels x disparities), the
            depth step grows as 1 / scale. The silhouette filter keeps the full-size masks.
        pair_budget: a pair whose SGM would cost more than the whole view searching a quarter of
            its longer side in disparities is matched on smaller rectified views (``_pair_points``'s
            ``max_cost``); False: every pair at full size (the dense step before the budget).
    """
    if not (isinstance(scale, (int, float)) and 0 < scale <= 1):
        raise ValueError(f"scale must be in (0, 1], got {scale!r}")
    cams = check_poses(cameras)
    if len(images) != len(cams) or len(masks) != len(cams):
        raise ValueError(f"{len(images)} images and {len(masks)} masks for {len(cams)} cameras")
    box = np.asarray(box, dtype=np.float64).reshape(2, 3)
    if center is None:
        center = box.mean(axis=0)
    g = np.zeros((0, 3)) if guide is None else np.asarray(guide, dtype=np.float64).reshape(-1, 3)
    g = g[crop_to_box(g, box[0], box[1])] if len(g) else g
    if len(g) < 10:
        axes = [np.linspace(box[0, k], box[1, k], 5) for k in range(3)]
        g = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    K_full, masks_full = K, masks
    if scale < 1 and len(images):
        images, masks, K = scaled_views(images, masks, K, scale)
    height, width = (int(n) for n in np.asarray(images[0]).shape[:2]) if len(images) else (16, 16)
    max_disp = max(16, (max(width, height) // 16) * 16)
    # a pair's SGM work at most that of the whole view searching a quarter of max_disp (_pair_points)
    max_cost = _sgm_cost(height, width, max_disp // 4) if pair_budget else None
    R, t = world_to_camera(cams)
    pairs = neighbour_pairs(cams, center, neighbours)
    if pair_inliers:
        chosen = overlap_pairs(pair_inliers, len(cams), neighbours)
        covered = {i for pair in chosen for i in pair}
        pairs = sorted(set(chosen) | {pr for pr in pairs if pr[0] not in covered or pr[1] not in covered})
    pts, cols, used = [], [], []
    for i, j in pairs:
        for a, b in ((i, j), (j, i)):          # the order with positive disparities succeeds
            p, c = _pair_points(images[a], images[b], np.asarray(masks[a], bool), np.asarray(masks[b], bool),
                                R[a], t[a], R[b], t[b], K, g, block, max_disp, max_cost)
            if len(p):
                pts.append(p)
                cols.append(c)
                used.append((a, b))
                break
    if not pts:
        return DenseResult(np.zeros((0, 3)), np.zeros((0, 3), np.uint8), used, 0, [])
    P = np.concatenate(pts)
    C = np.concatenate(cols)
    raw = len(P)
    keep = crop_to_box(P, box[0], box[1])
    P, C = P[keep], C[keep]
    if silhouette and len(P):
        keep = silhouette_filter(P, cams, K_full, masks_full)
        P, C = P[keep], C[keep]
    P, C = voxel_downsample(P, C, voxel)
    return DenseResult(P, C, used, raw, [len(p) for p in pts])
