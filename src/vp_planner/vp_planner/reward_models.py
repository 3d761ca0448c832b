"""Reward models: the paper's reward (eqs. 2-7) and a model of what the reconstruction recovers.

Every model maps camera plans z (B, N, 6) and the K wind realizations (K, P, 3) of the scene to
rewards (B,) in [0, 1], and keeps the paper's wind averaging (eq. 7): the reward of a plan is the
mean over the K realizations of its reward on each one.

``paper``
    Eqs. 2-7 exactly as :mod:`vp_planner.reward` implements them: the sine of the triangulation
    angle, summed over all camera pairs that see a point inside the FoV cone and meet at no more
    than theta_match, averaged over points and pairs.

``coverage``
    The expected fraction of the plant's points that some camera pair reconstructs. It models
    what the plan-quality study (``bench/plan_quality.py``) found decides the Chamfer distance:
    completeness, i.e. which parts of the plant end up with no reconstructed point at all::

        q_i(p)   = vis_i(p) rho(|p - c_i|)                     camera i images p usefully
        q_ij(p)  = q_i(p) q_j(p) w(theta_ij(p))                 pair (i, j) reconstructs p
        cov(p)   = 1 - prod_{i<j} (1 - q_ij(p))                  some pair does (saturation)
        R(z)     = 1/(K P) sum_k sum_p cov(p~^(k))               eq. 7's average over winds

    * vis_i(p): p lies inside camera i's *image* (the W x H frustum, not a cone) and is not
      hidden by nearer points of the same realization: a z-buffer of the cloud on a coarse grid
      of ``zbuffer_width`` cells across the image; p is visible when its depth is within
      ``occlusion_tolerance`` (relative) of the nearest depth in its cell (self-occlusion).
    * rho(r) = min(1, (f / r) / ppm_full): image resolution, pixels per metre on the plant at
      distance r (f = (W/2) / tan(FoV/2) for the rendered image size) relative to the density
      ``ppm_full`` above which more pixels no longer help.
    * w(theta): the matching window, the triangulation angle theta_ij(p) between c_i - p and
      c_j - p that SIFT matching and stereo handle: rising linearly to 1 at ``window_low``
      (small angles triangulate poorly), 1 up to ``window_high``, falling linearly to 0 at
      ``window_cutoff`` (wider pairs do not match).
    * 1 - prod(1 - q): per-point saturation; a point seen by one good pair is covered, ten
      pairs from the same side do not count ten times (the paper's sum does).

Each ingredient has its switch in :class:`CoverageParams` (the plan-quality benchmark's ablations).

``coverage-graph``
    ``coverage`` times the connectivity of the plan's view graph: under a flight the images must
    also hang together for SfM, which registers them through matched points. The realistic
    plan-quality study found plans with the highest coverage that came in tight pairs joined to
    one another by a few dozen matches, registered wrongly (README "Reward models")::

        m(theta)   = 1 up to match_full, linear to 0 at match_cutoff     SIFT under a change of view
        e_ij       = 1/(K P) sum_k sum_p q_i(p) q_j(p) m(theta_ij(p))     points pair (i, j) can match
        lambda_2   = 2nd-smallest eigenvalue of L = diag(E 1) - E          algebraic connectivity
        R_graph(z) = R(z) min(1, lambda_2 / graph_scale)

    lambda_2 (Fiedler 1973) is 0 exactly when the graph falls apart (some camera or group of
    cameras shares no matchable point with the rest: SfM cannot register it with them) and grows
    with the weakest cut between groups; ``graph_scale`` is where it stops mattering. e_ij is
    averaged over all realizations (one graph of the plan, as a flight has one set of images per
    wind) and ignores the point weights (registration needs shared points, reconstructed or not).
    The window and the scale were chosen on the design half of the realistic study alone.

``registration`` (an ingredient of ``coverage``, on by default)
    Under a flight the model is built from tracks and placed on the poses the drones reported
    (the anchored model: each connected part of the model, the cameras that share tracks, on its
    own reported centres and attitudes). A part whose cameras bunch together is placed badly: its
    scale and turn rest on a short lever. Cameras i and j are linked when the points both see,
    weighted by w(theta_ij), are at least ``link_overlap`` of what the one seeing less sees (as
    the reconstruction picks the pairs it matches, ``vp_recon/pairs.py``); the parts are the
    linked cameras closed under chaining. For the part g of camera i, the similarity
    (t, omega, s) fitted to its n_g centres (sigma_p) and attitudes (sigma_a) has, about the
    part's centroid (a_k = c_k - mean c, sum a_k = 0), the block-diagonal information (satellite
    navigation's dilution of precision)::

        I_t = n_g / sigma_p^2 I_3,   I_w = (sum_k |a_k|^2 I_3 - a_k a_k^T) / sigma_p^2 + n_g / sigma_a^2 I_3,
        I_s = sum_k |a_k|^2 / sigma_p^2

    and a point b = p - mean c moves by delta = t + omega x b + s b, so
    E|delta|^2 = 3 / I_t + |b|^2 (tr I_w^-1 + 1 / I_s) - b^T I_w^-1 b =: sigma_i(p)^2. With delta
    isotropic Gaussian, the probability that the point stays within tau is the chi(3) CDF
    g(x) = erf(x / sqrt 2) - sqrt(2 / pi) x exp(-x^2 / 2) at x = sqrt(3) tau / sigma, and
    q_ij(p) is multiplied by g at sigma = max(sigma_i(p), sigma_j(p)) for a pair within one part
    (0 for a pair across parts: it shares no track): R becomes the expected recall at tau of the
    evaluation's F-score. With ground control (``ground_control``: markers of surveyed position
    in the images, the realistic capture's default) the model as a whole is placed on the
    markers, which removes the error its G parts (of 2 cameras or more: a lone camera holds no
    point) have in common: sigma_i(p)^2 (1 - 1/G) is used instead, 0 for a model in one part.
    Degenerate: a part of one camera (or of coincident ones) has no scale (I_s = 0): g = 0; so a
    camera whose pairs all lie outside the window adds nothing. Not modelled: the model's shape
    within a part (the bundle adjustment from tracks), and which parts see the markers.
    The parts follow the pair rule at every N: the reconstruction matches every pair below 8
    cameras, but the pair rule also keeps the neighbours a dense stereo pair needs.

A second sortie (README "A second sortie"): every model takes the cameras already flown,
``fixed_cameras`` (M, 6), and scores a plan z together with them, R(z | F) = R(z ∪ F): pairs
between a new and a fixed camera count like pairs within the plan. It also takes point weights
w_p (:func:`reconstructed_weights`: ``reconstructed_weight`` for a point within ``tau`` of the
first sortie's reconstruction, 1 for the others); the averages over points become weighted
means, 1/(sum_p w_p) sum_p w_p cov(p) (and eq. 2 likewise), so the next views go to the holes.
Degenerate cases: a camera on a point or with a zero viewing vector sees nothing; an empty
cloud is refused; N < 2 is refused (no pairs).

Cost and memory: the camera terms are (B, N, K P), the pair terms (B, S, K P) with
S = N (N - 1) / 2; plans are processed in chunks and pairs in blocks so that no intermediate
array exceeds ``max_elements`` elements.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Callable, Optional, Union

import numpy as np
import torch

from vp_scene.camera import CameraModel, optical_axes

from .feasibility import check_realizations
from .reward import DEFAULT_FOV, DEFAULT_THETA_MATCH, noisy_reward, prepare_points

__all__ = ["RewardModel", "REGISTRY", "reward_model", "REWARD_MODELS", "DEFAULT_REWARD_MODEL", "ZBUFFER_CELLS", "CoverageParams", "RewardFunction", "make_reward",
           "coverage_reward", "point_coverage", "view_graph", "view_graph_factor", "model_parts",
           "placement_error", "within_tau", "check_reward_model",
           "reconstructed_weights", "reconstructed_mask",
           "DEFAULT_TAU", "DEFAULT_RECONSTRUCTED_WEIGHT", "check_fixed_cameras"]

#: A planning-cloud point within this distance (m) of the first sortie's reconstruction counts as
#: reconstructed (README "A second sortie").
DEFAULT_TAU: float = 0.03
#: The weight w_p of a reconstructed point (the others weigh 1).
DEFAULT_RECONSTRUCTED_WEIGHT: float = 0.1

#: Bounds of a camera's z-buffer grid (cells across the image, ``CoverageParams.zbuffer_width``).
ZBUFFER_CELLS: tuple[int, int] = (8, 1024)

#: The model the plan-quality study supports (README; results/ideal/plan_quality.json, and under the
#: realistic capture results/plan_quality.json).
DEFAULT_REWARD_MODEL: str = "coverage"

RewardFunction = Callable[[Any], np.ndarray]


def check_reward_model(name: Any) -> str:
    """``name`` if it is one of :data:`REWARD_MODELS`, else ValueError naming the choices."""
    return reward_model(name).name


def reward_model(name: Any) -> "RewardModel":
    """The registry's entry of ``name`` (:data:`REGISTRY`), else ValueError naming the choices."""
    if not isinstance(name, str) or name not in _BY_NAME:
        raise ValueError(f"unknown reward model {name!r}; one of {', '.join(REWARD_MODELS)}")
    return _BY_NAME[name]


@dataclass(frozen=True)
class CoverageParams:
    """Ingredients of the ``coverage`` model (see the module docstring); angles in degrees.

    Attributes:
        occlusion: z-buffer self-occlusion test.
        zbuffer_width: z-buffer cells across the image width (height in proportion).
        occlusion_tolerance: a point within this fraction of the cell's nearest depth is visible.
        resolution: weight cameras by pixels per metre on the plant.
        ppm_full: pixels per metre above which rho = 1.
        window: the matching window on the triangulation angle (else every angle counts 1,
            up to ``window_cutoff``).
        window_low, window_high, window_cutoff: the window's corners.
        saturation: per-point 1 - prod(1 - q) (else the mean of q over pairs, as the paper).
        frustum: the rectangular W x H image (else the paper's cone of half-angle FoV/2).
        max_points: subsample each realization to at most this many points (0: all).
        view_graph: multiply by the view graph's connectivity (``coverage-graph``).
        match_full, match_cutoff: m(theta) of the view graph, degrees.
        graph_scale: lambda_2 at and above which the graph counts as fully connected.
        registration: weigh each pair by the probability that the point it reconstructs lands
            within ``registration_tau`` of the truth once its part of the model is placed on the
            reported poses (``registration``, module docstring).
        position_sigma, attitude_sigma: the reported centres' (m) and attitudes' (degrees) error.
        link_overlap: cameras i, j belong to one part of the model when the points both see
            (vis_i vis_j) weighted by the window w(theta_ij) are at least this share of what the
            one seeing less sees (the reconstruction's pair rule: 10 %).
        registration_tau: metres (the F-score's threshold of the evaluation).
        ground_control: markers on the ground place the model as a whole (the realistic
            capture's default), so only where its parts lie relative to one another counts.
    """

    occlusion: bool = True
    zbuffer_width: int = 64
    occlusion_tolerance: float = 0.03
    resolution: bool = True
    ppm_full: float = 500.0
    window: bool = True
    window_low: float = 5.0
    window_high: float = 25.0
    window_cutoff: float = 45.0
    saturation: bool = True
    frustum: bool = True
    max_points: int = 3000
    # the view graph's window and scale: chosen on the design half of the realistic plan-quality study
    view_graph: bool = False
    match_full: float = 10.0
    match_cutoff: float = 30.0
    graph_scale: float = 1e-3
    # the reported poses' accuracy (the drone's RTK and gimbal, not fitted) and the F-score's tau
    registration: bool = True
    position_sigma: float = 0.02
    attitude_sigma: float = 0.5
    link_overlap: float = 0.1
    registration_tau: float = 0.02
    ground_control: bool = True

    def __post_init__(self) -> None:
        if not ZBUFFER_CELLS[0] <= int(self.zbuffer_width) <= ZBUFFER_CELLS[1]:
            raise ValueError(f"zbuffer_width must be in [{ZBUFFER_CELLS[0]}, {ZBUFFER_CELLS[1]}], got {self.zbuffer_width}")

    def unoccluded(self, inside: torch.Tensor, depth: torch.Tensor, u: torch.Tensor, v: torch.Tensor, K: int,
                   image: CameraModel) -> torch.Tensor:
        """vis_i (B, N, K P): ``inside`` and not hidden by a nearer point of its realization in its
        cell of the z-buffer (``zbuffer_width`` cells across the image at image coordinates u, v =
        x / depth, y / depth). One buffer per (plan, camera, realization): points of other winds
        do not occlude. A subclass may size the cells otherwise (the plan-quality benchmark's
        ablations do)."""
        B, N, KP = inside.shape
        tx, ty = image.tan_half_fov, image.tan_half_fov_vertical
        k_of = torch.arange(K).repeat_interleave(KP // K).view(1, 1, KP)
        bn = torch.arange(B * N).view(B, N, 1)
        gw = max(1, int(self.zbuffer_width))
        gh = max(1, int(round(gw * image.height / image.width)))
        iu = ((u / tx + 1.0) * 0.5 * gw).floor().clamp(0, gw - 1).long()
        iv = ((v / ty + 1.0) * 0.5 * gh).floor().clamp(0, gh - 1).long()
        key = ((bn * K + k_of) * gh + iv) * gw + iu
        inf = torch.full((B * N * K * gh * gw,), math.inf, dtype=depth.dtype)
        zmin = inf.scatter_reduce(0, key[inside], depth[inside], reduce="amin", include_self=True)
        return inside & (depth <= zmin[key.clamp_min(0)] * (1.0 + self.occlusion_tolerance))


def _window(theta_deg: torch.Tensor, p: CoverageParams) -> torch.Tensor:
    """w(theta): linear rise to 1 at window_low, flat to window_high, linear fall to 0 at cutoff."""
    if not p.window:
        return (theta_deg <= p.window_cutoff).to(theta_deg.dtype)
    rise = (theta_deg / max(p.window_low, 1e-9)).clamp(0.0, 1.0)
    fall = ((p.window_cutoff - theta_deg) / max(p.window_cutoff - p.window_high, 1e-9)).clamp(0.0, 1.0)
    return torch.minimum(rise, fall)


def coverage_reward(cameras: Any, realizations: Any, params: CoverageParams = CoverageParams(),
                    image: CameraModel = CameraModel(), *, max_elements: int = 1 << 22,
                    dtype: torch.dtype = torch.float32, seed: int = 0, weights: Any = None) -> np.ndarray:
    """The ``coverage`` model (module docstring) of plans (..., N, 6) on realizations (K, P, 3).

    ``weights``: None, or (K, P) point weights w_p >= 0 (the weighted mean over points; taken as
    they are, so give them for the points after any subsampling: ``params.max_points = 0``).
    Returns rewards of shape ``cameras.shape[:-2]`` (a float for one (N, 6) plan).
    """
    cams = torch.as_tensor(np.asarray(cameras, dtype=np.float64)).to(dtype)
    if cams.ndim < 2 or cams.shape[-1] != 6:
        raise ValueError(f"cameras must have shape (..., N, 6), got {tuple(cams.shape)}")
    batch_shape = tuple(cams.shape[:-2])
    N = cams.shape[-2]
    if N < 2:
        raise ValueError(f"the reward needs at least 2 cameras (pairs), got N = {N}")
    pts = _points(realizations, params.max_points, seed).to(dtype)  # (K, P, 3)
    K, P, _ = pts.shape
    w = None
    if weights is not None:
        w = torch.as_tensor(_check_weights(weights, (K, P))).reshape(-1).to(dtype)
        w = w / max(float(w.sum()), 1e-300)
    cams = cams.reshape(-1, N, 6)
    B = cams.shape[0]
    out = torch.zeros(B, dtype=torch.float64)
    S = N * (N - 1) // 2
    per_plan = K * P * max(3 * N, min(S, 64))
    chunk = max(1, max_elements // max(1, per_plan))
    for b0 in range(0, B, chunk):
        cov, E = _point_coverage(cams[b0:b0 + chunk], pts, params, image, max_elements)
        # 1/(K P) sum_k sum_p (eq. 7), or the w_p-weighted mean
        r = cov.mean(-1) if w is None else cov @ w
        if params.view_graph:
            r = r * view_graph_factor(E, params.graph_scale)
        out[b0:b0 + chunk] = r.to(torch.float64)
    res = out.numpy()
    return res.reshape(batch_shape) if batch_shape else float(res.reshape(-1)[0])


def _subsample(num_points: int, max_points: int, seed: int) -> Optional[np.ndarray]:
    """The indices of the points kept (sorted), or None when all are."""
    if max_points and num_points > max_points:
        return np.sort(np.random.default_rng(seed).choice(num_points, size=max_points, replace=False))
    return None


def _points(realizations: Any, max_points: int, seed: int) -> torch.Tensor:
    R = torch.as_tensor(check_realizations(realizations))  # (K, P, 3), validated
    idx = _subsample(R.shape[1], max_points, seed)
    return R if idx is None else R[:, torch.as_tensor(idx)]


def _check_weights(weights: Any, shape: tuple) -> np.ndarray:
    """Point weights of the given (K, P) shape, finite and >= 0 (a (P,) vector is repeated over K)."""
    w = np.asarray(weights, dtype=np.float64)
    if w.ndim == 1 and len(shape) == 2:
        w = np.broadcast_to(w, shape)
    if w.shape != tuple(shape):
        raise ValueError(f"point weights must have shape {tuple(shape)} (one a point), got {w.shape}")
    if not (np.all(np.isfinite(w)) and np.all(w >= 0)):
        raise ValueError("point weights must be finite and >= 0")
    return w


def check_fixed_cameras(fixed_cameras: Any) -> np.ndarray:
    """Cameras already flown as a finite (M, 6) array with non-zero viewing vectors (M may be 0);
    ValueError otherwise."""
    F = np.zeros((0, 6)) if fixed_cameras is None else np.asarray(fixed_cameras, dtype=np.float64)
    if F.size == 0:
        return np.zeros((0, 6))
    if F.ndim != 2 or F.shape[1] != 6:
        raise ValueError(f"fixed cameras must have shape (M, 6) [cx cy cz vx vy vz], got {F.shape}")
    bad = ~np.isfinite(F).all(axis=1) | (np.linalg.norm(np.nan_to_num(F[:, 3:]), axis=1) == 0)
    if bad.any():
        raise ValueError(f"fixed camera {int(np.flatnonzero(bad)[0])} of {len(F)} is not finite or has a zero "
                         f"viewing direction")
    return F


def reconstructed_mask(realizations: Any, reconstruction: Any, tau: float = DEFAULT_TAU) -> np.ndarray:
    """(K, P) True where a point of the planning cloud is reconstructed: min_q |p - q| <= tau over
    the reconstruction's points q (a KD-tree; each realization's points on their own).
    ValueError for a non-finite reconstruction or tau < 0; an empty reconstruction marks nothing."""
    R = check_realizations(realizations)
    if not (math.isfinite(tau) and tau >= 0):
        raise ValueError(f"tau must be finite and >= 0, got {tau}")
    Q = np.asarray(reconstruction, dtype=np.float64).reshape(-1, 3)
    if not np.all(np.isfinite(Q)):
        raise ValueError("the reconstruction contains non-finite coordinates")
    if not len(Q):
        return np.zeros(R.shape[:2], dtype=bool)
    from scipy.spatial import cKDTree

    reach = tau * (1 + 1e-12) + 1e-15
    dist, _ = cKDTree(Q).query(R.reshape(-1, 3), k=1, distance_upper_bound=reach)
    return (dist <= reach).reshape(R.shape[:2])


def reconstructed_weights(realizations: Any, reconstruction: Any, tau: float = DEFAULT_TAU,
                          reconstructed_weight: float = DEFAULT_RECONSTRUCTED_WEIGHT) -> np.ndarray:
    """Point weights w_p (K, P) of the planning cloud given what a sortie reconstructed::

        w_p = reconstructed_weight   if min_q |p - q| <= tau (:func:`reconstructed_mask`)
        w_p = 1                      otherwise (a hole)

    ValueError as :func:`reconstructed_mask`, or for a weight outside [0, 1]."""
    if not (math.isfinite(reconstructed_weight) and 0.0 <= reconstructed_weight <= 1.0):
        raise ValueError(f"reconstructed_weight must be in [0, 1], got {reconstructed_weight}")
    return np.where(reconstructed_mask(realizations, reconstruction, tau), float(reconstructed_weight), 1.0)


def _match_window(theta_deg: torch.Tensor, p: CoverageParams) -> torch.Tensor:
    """m(theta) of the view graph: 1 up to match_full, linear to 0 at match_cutoff."""
    return ((p.match_cutoff - theta_deg) / max(p.match_cutoff - p.match_full, 1e-9)).clamp(0.0, 1.0)


def view_graph_factor(E: torch.Tensor, scale: float) -> torch.Tensor:
    """min(1, lambda_2 / scale) of view graphs E (B, N, N) (``coverage-graph``): lambda_2 is the
    algebraic connectivity, the second-smallest eigenvalue of the Laplacian diag(E 1) - E; 0 for
    a graph that falls apart. ValueError for a scale <= 0."""
    if not (math.isfinite(scale) and scale > 0):
        raise ValueError(f"graph_scale must be finite and > 0, got {scale}")
    L = torch.diag_embed(E.sum(-1)) - E
    lam2 = torch.linalg.eigvalsh(L.to(torch.float64))[..., 1]
    return (lam2 / scale).clamp(0.0, 1.0).to(E.dtype)


def model_parts(E: torch.Tensor, link: float) -> torch.Tensor:
    """Same-part matrix (B, N, N) bool of pair shares E (B, N, N): i and j in one connected part
    of the graph whose edges are e_ij >= ``link`` (reachability by repeated squaring).
    ``coverage``'s registration links on the pairs' overlaps (``link_overlap``)."""
    N = E.shape[-1]
    A = ((E >= link) | torch.eye(N, dtype=torch.bool)).to(torch.float64)
    for _ in range(max(1, math.ceil(math.log2(max(N, 2))))):
        A = ((A @ A) > 0).to(torch.float64)
    return A > 0


def placement_error(cams: torch.Tensor, parts: torch.Tensor, points: torch.Tensor, position_sigma: float,
                    attitude_sigma_deg: float) -> torch.Tensor:
    """sigma_i(p)^2 (B, N, M): the mean squared displacement of points (M, 3) when camera i's
    part of the model is placed by the similarity fitted to the part's reported centres and
    attitudes (module docstring, ``registration``). ``cams`` (B, N, 6+), ``parts`` (B, N, N) bool
    from :func:`model_parts`. inf for a part without scale (one camera, or coincident ones)."""
    dt = cams.dtype
    c = cams[..., :3]
    m = parts.to(dt)                                               # (B, N, N): m[b, i, k] = k in i's part
    n = m.sum(-1)                                                  # (B, N)
    centre = (m @ c) / n[..., None]                                # (B, N, 3)
    a = c[:, None, :, :] - centre[:, :, None, :]                   # (B, N, N, 3): a_k about i's part
    a = a * m[..., None]
    a2 = (a * a).sum(-1).sum(-1)                                   # sum_k |a_k|^2, (B, N)
    eye = torch.eye(3, dtype=dt)
    sp2 = position_sigma ** 2
    Iw = (a2[..., None, None] * eye - torch.einsum("bikx,biky->bixy", a, a)) / sp2 \
        + (n / math.radians(attitude_sigma_deg) ** 2)[..., None, None] * eye
    Cw = torch.linalg.inv(Iw)                                      # (B, N, 3, 3)
    var_s = torch.where(a2 > 1e-12, sp2 / a2.clamp_min(1e-12), torch.full_like(a2, math.inf))
    b = points.to(dt)[None, None, :, :] - centre[:, :, None, :]    # (B, N, M, 3)
    bb = (b * b).sum(-1)
    bCb = torch.einsum("bimx,bixy,bimy->bim", b, Cw, b)
    tr = Cw.diagonal(dim1=-2, dim2=-1).sum(-1)
    var = (3 * sp2 / n)[..., None] + bb * (tr + var_s.clamp(max=1e30))[..., None] - bCb
    return torch.where(torch.isinf(var_s)[..., None], torch.full_like(var, math.inf), var)


def within_tau(var: torch.Tensor, tau: float) -> torch.Tensor:
    """P(|delta| < tau) for an isotropic Gaussian delta with E|delta|^2 = var: the chi(3) CDF at
    x = sqrt(3) tau / sqrt(var) (0 where var is inf, 1 where it is 0)."""
    x = math.sqrt(3.0) * tau / var.clamp_min(1e-30).sqrt()
    return (torch.erf(x / math.sqrt(2.0)) - math.sqrt(2.0 / math.pi) * x * torch.exp(-0.5 * x * x)).clamp(0.0, 1.0)


def _one_plan(cameras: Any) -> torch.Tensor:
    """One plan (N, 6) as a batch (1, N, 6) in float64; ValueError for N < 2 (no pairs)."""
    cams = torch.as_tensor(np.asarray(cameras, dtype=np.float64)).reshape(1, -1, 6)
    if cams.shape[1] < 2:
        raise ValueError(f"the reward needs at least 2 cameras (pairs), got N = {cams.shape[1]}")
    return cams


def view_graph(cameras: Any, realizations: Any, params: CoverageParams = CoverageParams(),
               image: CameraModel = CameraModel()) -> np.ndarray:
    """The view graph E (N, N) of one plan (``coverage-graph``, module docstring): e_ij, the share
    of the realizations' points cameras i and j both image usefully within the matching window."""
    cams = _one_plan(cameras)
    _, E = _point_coverage(cams, _points(realizations, params.max_points, 0),
                           replace(params, view_graph=True, registration=False), image, 1 << 22)
    return E[0].numpy()


def _point_coverage(cams: torch.Tensor, pts: torch.Tensor, p: CoverageParams, image: CameraModel,
                    max_elements: int) -> tuple[torch.Tensor, torch.Tensor]:
    """cov(p) (B, K P) of plans (B, N, 6) on realizations (K, P, 3), flattened realization-major,
    and the view graph E (B, N, N) (zeros unless ``p.view_graph``)."""
    B, N, _ = cams.shape
    K, P, _ = pts.shape
    dt = cams.dtype
    c, x_o, y_o, z_o = optical_axes(cams)
    valid_cam = torch.isfinite(cams).all(-1) & (torch.linalg.vector_norm(cams[..., 3:], dim=-1) > 0)
    flat = pts.reshape(1, 1, K * P, 3)
    d = flat - c[:, :, None, :]                                     # (B, N, KP, 3): p - c_i
    r = torch.linalg.vector_norm(d, dim=-1)                          # (B, N, KP)
    depth = (d * z_o[:, :, None, :]).sum(-1)
    xs = (d * x_o[:, :, None, :]).sum(-1)
    ys = (d * y_o[:, :, None, :]).sum(-1)
    front = (depth > 1e-6) & valid_cam[:, :, None] & (r > 1e-9)
    safe = torch.where(front, depth, torch.ones_like(depth))
    tx, ty = image.tan_half_fov, image.tan_half_fov_vertical
    if p.frustum:
        u, v = xs / safe, ys / safe
        inside = front & (u.abs() <= tx) & (v.abs() <= ty)
    else:  # the paper's cone: angle between v and p - c at most FoV / 2
        inside = front & (depth >= math.cos(0.5 * image.fov) * r)
        u = (xs / safe).clamp(-tx, tx)
        v = (ys / safe).clamp(-ty, ty)
    vis = p.unoccluded(inside, depth, u, v, K, image) if p.occlusion else inside
    q = vis.to(dt)
    seen_pt = q                                                    # visible (registration's links: any resolution)
    if p.resolution:
        q = q * ((image.focal_px / r.clamp_min(1e-9)) / p.ppm_full).clamp(max=1.0)
    unit = d / r.clamp_min(1e-12)[..., None]
    ii, jj = torch.triu_indices(N, N, offset=1)
    S = ii.numel()
    log_miss = torch.zeros(B, K * P, dtype=dt)
    total = torch.zeros(B, K * P, dtype=dt)
    E = torch.zeros(B, N, N, dtype=dt)
    block = max(1, max_elements // max(1, 3 * B * K * P))

    def angles(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
        cos = (unit[:, a] * unit[:, b]).sum(-1).clamp(-1.0, 1.0)    # (B, s, KP)
        return torch.rad2deg(torch.arccos(cos))

    var = None
    if p.registration:  # the pairs' overlaps first (a pass of their own), then sigma_i(p)^2 of each camera's part
        L = torch.zeros(B, N, N, dtype=dt)
        for s0 in range(0, S, block):
            a, b = ii[s0:s0 + block], jj[s0:s0 + block]
            e = (seen_pt[:, a] * seen_pt[:, b] * _window(angles(a, b), p)).mean(-1)
            L[:, a, b] = e
            L[:, b, a] = e
        seen = seen_pt.mean(-1)                                    # (B, N): what each camera images
        same = model_parts(L / torch.minimum(seen[:, :, None], seen[:, None, :]).clamp_min(1e-12),
                           p.link_overlap)
        var = placement_error(cams, same, flat[0, 0], p.position_sigma, p.attitude_sigma)
        if p.ground_control:  # the markers place the whole: what the G parts share is gone
            size = same.to(dt).sum(-1)                              # (B, N): cameras in camera i's part
            G = ((size > 1.5).to(dt) / size).sum(-1)                # parts of 2 cameras or more (a lone one: no point)
            var = torch.where((G > 1.5)[:, None, None], var * (1.0 - 1.0 / G.clamp_min(1.0))[:, None, None],
                              torch.zeros_like(var))
    for s0 in range(0, S, block):
        a, b = ii[s0:s0 + block], jj[s0:s0 + block]
        theta = angles(a, b)
        qq = q[:, a] * q[:, b]
        qij = qq * _window(theta, p)
        if var is not None:  # within a part only, the point within tau once placed (module docstring)
            qij = qij * same[:, a, b, None].to(dt) * within_tau(torch.maximum(var[:, a], var[:, b]),
                                                                p.registration_tau)
        if p.view_graph:  # e_ij: the mean over all K P points
            e = (qq * _match_window(theta, p)).mean(-1)
            E[:, a, b] = e
            E[:, b, a] = e
        if p.saturation:
            log_miss += torch.log1p(-qij.clamp(max=1.0 - 1e-7)).sum(1)
        else:
            total += qij.sum(1)
    cov = -torch.expm1(log_miss) if p.saturation else total / S      # cov(p), (B, K P)
    return cov, E


def point_coverage(cameras: Any, realizations: Any, params: CoverageParams = CoverageParams(),
                   image: CameraModel = CameraModel()) -> np.ndarray:
    """cov(p) of every point (K, P) of the realizations for one plan (N, 6), all points kept."""
    cams = _one_plan(cameras)
    pts = _points(realizations, 0, 0)
    cov, _ = _point_coverage(cams, pts, params, image, 1 << 22)
    return cov.reshape(pts.shape[0], pts.shape[1]).numpy()


def make_reward(spec: Union[str, tuple], realizations: Any, fov: float = DEFAULT_FOV,
                theta_match: float = DEFAULT_THETA_MATCH, image: CameraModel | None = None,
                dtype: torch.dtype = torch.float64, fixed_cameras: Any = None,
                point_weights: Any = None) -> RewardFunction:
    """A function cams (..., N, 6) -> rewards of the named model on these realizations.

    ``spec`` is a name of :data:`REWARD_MODELS` or ``(name, CoverageParams)`` (the parameters of a
    model that takes them, :attr:`RewardModel.coverage`; the others ignore them). ``image``
    gives the image size the resolution term uses (default 2000 x 1500, the paper's) and its
    field of view is ``fov``. ``fixed_cameras`` (M, 6): cameras already flown, scored with every
    plan (R(z ∪ F), module docstring); ``point_weights`` (K, P): w_p of every point (None: 1).
    """
    name, params = (spec, None) if isinstance(spec, str) else spec
    model = reward_model(name)
    F = check_fixed_cameras(fixed_cameras)
    R = check_realizations(realizations)
    W = None if point_weights is None else _check_weights(point_weights, R.shape[:2])
    return model.make(R, W, F, fov, theta_match, image, dtype, params)


def _with_fixed(cams: Any, F: np.ndarray) -> np.ndarray:
    """The plans (..., N, 6) with the fixed cameras F (M, 6) appended: (..., N + M, 6)."""
    z = np.asarray(cams, dtype=np.float64)
    if not len(F) or z.ndim < 2:
        return z
    return np.concatenate([z, np.broadcast_to(F, z.shape[:-2] + F.shape)], axis=-2)


def _paper_reward(R: np.ndarray, W: Optional[np.ndarray], F: np.ndarray, fov: float, theta_match: float,
                  image: Optional[CameraModel], dtype: torch.dtype, params: None) -> RewardFunction:
    """``paper``: eqs. 2-7 (:func:`vp_planner.reward.noisy_reward`), in ``dtype``; no image size."""
    prep = prepare_points(R, dtype, W)

    def paper(cams: Any) -> np.ndarray:
        return np.asarray(noisy_reward(_with_fixed(cams, F), prep, fov, theta_match, dtype=dtype))
    return paper


def _coverage_reward(R: np.ndarray, W: Optional[np.ndarray], F: np.ndarray, fov: float, theta_match: float,
                     image: Optional[CameraModel], dtype: torch.dtype, params: CoverageParams) -> RewardFunction:
    """The ``coverage`` family: :func:`coverage_reward` of ``params`` on the realizations subsampled
    once (``max_points``), with ``image``'s size at field of view ``fov``; its window stands for
    theta_match and it sums in float32 whatever ``dtype``."""
    image = image or CameraModel(fov=fov)
    if abs(image.fov - fov) > 1e-12:
        image = CameraModel(image.width, image.height, fov)
    idx = _subsample(R.shape[1], params.max_points, 0)
    pts = R if idx is None else R[:, idx]
    w = None if W is None else (W if idx is None else W[:, idx])
    flat = replace(params, max_points=0)

    def coverage(cams: Any) -> np.ndarray:
        return np.asarray(coverage_reward(_with_fixed(cams, F), pts, flat, image, weights=w))
    return coverage


@dataclass(frozen=True)
class RewardModel:
    """One reward model of the registry: its ``name`` (the ``reward`` parameter, the PlanViews goal
    field, ``--reward``), a one-line ``summary``, whether it is of the ``coverage`` family (it
    takes :class:`CoverageParams`, its registration term the flight's reported-pose errors, and
    ``fixes`` the flags its name sets whatever the parameters say), and ``build``, how it is made
    on the checked realizations: ``build(R, W, F, fov, theta_match, image, dtype, params)``
    (:meth:`make`)."""

    name: str
    summary: str
    build: Callable[..., RewardFunction]
    coverage: bool = True
    fixes: tuple[tuple[str, Any], ...] = ()

    def params(self, params: Optional[CoverageParams] = None) -> Optional[CoverageParams]:
        """The model's :class:`CoverageParams` (None for a model that takes none): ``params`` (or
        the defaults) with the flags the name fixes."""
        if not self.coverage:
            return None
        return replace(params or CoverageParams(), **dict(self.fixes))

    def make(self, R: np.ndarray, W: Optional[np.ndarray], F: np.ndarray, fov: float, theta_match: float,
             image: Optional[CameraModel], dtype: torch.dtype, params: Optional[CoverageParams] = None
             ) -> RewardFunction:
        """The reward function on checked realizations R (K, P, 3), point weights W (K, P) or None
        and fixed cameras F (M, 6) (:func:`make_reward` checks them)."""
        return self.build(R, W, F, fov, theta_match, image, dtype, self.params(params))


#: The reward models (one home): names, what each is, how each is made.
REGISTRY: tuple[RewardModel, ...] = (
    RewardModel("paper", "eqs. 2-7", _paper_reward, coverage=False),
    RewardModel("coverage", "expected reconstructed fraction", _coverage_reward),
    RewardModel("coverage-graph", "coverage times the view graph's connectivity", _coverage_reward,
                fixes=(("view_graph", True),)),
)
_BY_NAME: dict[str, RewardModel] = {m.name: m for m in REGISTRY}
#: Reward models by name (``reward`` parameter, PlanViews goal field, ``--reward``).
REWARD_MODELS: tuple[str, ...] = tuple(_BY_NAME)
