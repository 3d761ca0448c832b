"""The ``coverage`` model's ablations the plan-quality study scores (``bench/plan_quality.py``):
each ingredient switched off, and z-buffer cells sized on the plant rather than on the image (an
option of the study, not of the planner).

:class:`ObjectCells` sizes each camera's z-buffer cells so that a cell measures ``cell`` metres
on the plant at the median depth D of what the camera sees in that realization,
2 tan(FoV/2) D / cell cells across (clamped to :data:`vp_planner.reward_models.ZBUFFER_CELLS`):
a leaf hides about its width whatever the distance. The median depth is each realization's own,
so that eq. 7's mean over the winds stays the mean of the rewards of each wind. The grids (up to
1024 x 768 cells a camera) keep only the cells some point falls in (``torch.unique`` of the cell
keys), so their memory follows the points.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import torch

from vp_planner.reward_models import ZBUFFER_CELLS, CoverageParams
from vp_scene.camera import CameraModel

__all__ = ["ObjectCells", "ablations"]


@dataclass(frozen=True)
class ObjectCells(CoverageParams):
    """``coverage`` with z-buffer cells of ``cell`` metres on the plant (module docstring)."""

    cell: float = 0.03

    def __post_init__(self) -> None:
        if not (math.isfinite(self.cell) and self.cell > 0):
            raise ValueError(f"cell must be finite and > 0 (metres), got {self.cell}")

    def unoccluded(self, inside: torch.Tensor, depth: torch.Tensor, u: torch.Tensor, v: torch.Tensor, K: int,
                   image: CameraModel) -> torch.Tensor:
        B, N, KP = inside.shape
        dt = depth.dtype
        tx, ty = image.tan_half_fov, image.tan_half_fov_vertical
        k_of = torch.arange(K).repeat_interleave(KP // K).view(1, 1, KP)
        bn = torch.arange(B * N).view(B, N, 1)
        seen = torch.where(inside, depth, torch.full((), math.nan, dtype=dt)).view(B, N, K, KP // K)
        d_med = torch.nan_to_num(seen.nanmedian(dim=-1).values, nan=1.0)    # a camera seeing nothing: any grid
        gw = (2.0 * image.tan_half_fov * d_med / self.cell).round().clamp(*ZBUFFER_CELLS).long()
        gw = gw.repeat_interleave(KP // K, dim=-1)
        gh = (gw.to(torch.float64) * image.height / image.width).round().clamp_min(1).long()
        iu = torch.minimum(((u / tx + 1.0) * 0.5 * gw).floor().clamp_min(0), (gw - 1).to(dt)).long()
        iv = torch.minimum(((v / ty + 1.0) * 0.5 * gh).floor().clamp_min(0), (gh - 1).to(dt)).long()
        stride = ZBUFFER_CELLS[1] + 1
        key = ((bn * K + k_of) * stride + iv) * stride + iu
        cells, which = torch.unique(key[inside], return_inverse=True)
        z_in = depth[inside]
        zmin = torch.full((len(cells),), math.inf, dtype=dt).scatter_reduce(0, which, z_in, reduce="amin")
        vis = torch.zeros_like(inside)
        vis[inside] = z_in <= zmin[which] * (1.0 + self.occlusion_tolerance)
        return vis


def ablations() -> dict[str, tuple[str, CoverageParams]]:
    """The ablations of ``coverage`` the study scores: name -> reward spec."""
    base = CoverageParams()
    return {
        "coverage-no-occlusion": ("coverage", replace(base, occlusion=False)),
        "coverage-no-resolution": ("coverage", replace(base, resolution=False)),
        "coverage-no-window": ("coverage", replace(base, window=False)),
        "coverage-no-saturation": ("coverage", replace(base, saturation=False)),
        "coverage-cone": ("coverage", replace(base, frustum=False)),
        "coverage-object-cells": ("coverage", ObjectCells()),
    }
