#!/usr/bin/env python3
"""Plant masks for any plant colour (issue 41, part 2): each segmentation against the renderer's
oracle, and on a real scan.

Renders: one plant (procedural, and Corn50 when ``../shared`` has it) in its own colours and
recoloured (its shading kept): ``yellow``, ``senescent`` (the lower half of the plant brown),
``brown``, ``purple``; 8 ring views and a top view at 640 x 480 over the soil with the realistic
capture's 4 ground markers and its sensor noise (the views of the excess-green threshold's
measurement, :data:`vp_recon.segment.EXG_THRESHOLD`). Every method of :func:`vp_recon.segment.flight_masks` is
scored by its IoU against the segmentation pass (mean and worst view): ``exg``, ``background``
(samples from the border band), ``background+box`` (samples outside the prior's box projected)
and ``auto+box`` (what a reconstruction with a prior uses), with ``auto``'s choice and its share
(excess-green pixels over the background model's).

Real scan (``--scan FOLDER``, any flight folder; none: skipped): no oracle, so the masks are
judged by what the reconstruction keeps: ``--views`` evenly spaced images reconstructed (sparse
and dense) with each method, the points kept and the images registered; ``+box``: with a prior,
the largest connected part of the ``exg`` reconstruction's cloud (a first pass,
:func:`bench.bench_real.clean_prior`), whose box the background model learns outside of and the
reconstruction is cropped to; ``--png`` writes the masks of three views side by side for a look.

    python -m bench.bench_masks [--scan FOLDER] [--views 12] [--png out/masks_real.png] [--out results]
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

if not __package__:  # python bench/bench_masks.py: as python -m bench.bench_masks (bench/_script.py)
    import _script  # noqa: F401
from bench.common import CORN50, ROOT, machine, write_report  # noqa: E402

#: Colours of the recoloured plant (RGB at the plant's mean brightness); None: its own.
COLOURS = {"natural": None, "yellow": (205, 185, 70), "senescent": "senescent", "brown": (125, 85, 50),
           "purple": (115, 50, 125)}
#: The methods scored on the renders: (label, mask method, with the prior's box).
METHODS = (("exg", "exg", False), ("background", "background", False), ("background+box", "background", True),
           ("auto+box", "auto", True))
#: The methods a real scan is reconstructed with: (label, mask method, with a prior).
REAL_METHODS = (("exg", "exg", False), ("background", "background", False), ("auto", "auto", False),
                ("background+box", "background", True), ("auto+box", "auto", True))


def recolour(meshes: list, rgb) -> list:
    """The meshes in the colour ``rgb``, each vertex keeping its brightness relative to the mean;
    ``'senescent'``: the vertices below the plant's median height brown, the others as they are."""
    if rgb == "senescent":
        zmed = np.median(np.concatenate([np.asarray(m.vertices)[:, 2] for m in meshes]))
        out = []
        for m, b in zip(meshes, recolour(meshes, COLOURS["brown"])):
            c = np.asarray(m.visual.vertex_colors).copy()
            low = np.asarray(m.vertices)[:, 2] < zmed
            c[low] = np.asarray(b.visual.vertex_colors)[low]
            m = m.copy()
            m.visual.vertex_colors = c
            out.append(m)
        return out
    out = []
    for m in meshes:
        m = m.copy()
        c = np.asarray(m.visual.vertex_colors).astype(float)
        lum = c[:, :3].mean(axis=1)
        c[:, :3] = np.clip(np.asarray(rgb, float)[None] * (lum / max(lum.mean(), 1e-9))[:, None], 0, 255)
        m.visual.vertex_colors = c.astype(np.uint8)
        out.append(m)
    return out


def views() -> np.ndarray:
    """8 ring views 45 degrees apart at 1.4 m and a top view (the EXG_THRESHOLD measurement's)."""
    a = np.deg2rad(45.0 * np.arange(8))
    c = np.stack([1.4 * np.cos(a), 1.4 * np.sin(a), np.full(8, 1.2)], axis=1)
    return np.concatenate([np.concatenate([c, [0.0, 0.0, 0.9] - c], axis=1), [[0.3, 0.2, 2.8, -0.3, -0.2, -1.9]]])


def render_cells(width: int, height: int) -> dict:
    """IoU of every method on every plant and colour (module docstring)."""
    from vp_recon.segment import flight_masks
    from vp_scene.meshing import scene_meshes
    from vp_recon.pipeline import crop_box
    from vp_scene.render import Renderer, marker_meshes
    from vp_scene.build import build_noisy_scene
    from vp_scene.capture import REALISTIC

    plants = {"procedural": None} | ({"corn50": str(CORN50)} if CORN50.is_dir() else {})
    cams = views()
    renderer = Renderer(width, height)
    cells = {}
    for plant, models in plants.items():
        ns, _ = build_noisy_scene("one_plant", models=models, seed=0, points_per_plant=3000, realizations=1)
        markers, _ = REALISTIC.lay_markers(ns.points)
        base, box = scene_meshes(ns, 0, None), crop_box(ns.points, 0.05)
        for colour, rgb in COLOURS.items():
            meshes = base if rgb is None else recolour(base, rgb)
            images, oracle, _ = renderer.render(meshes, cams, ground=True,
                                                markers=marker_meshes(markers, REALISTIC.gcp_size))
            images = [REALISTIC.expose(im, 0, i) for i, im in enumerate(images)]
            row = {}
            for label, method, with_box in METHODS:
                t0 = time.perf_counter()
                kw = dict(cameras=cams, K=renderer.K, box=box) if with_box else {}
                masks, choice = flight_masks(images, method, **kw)
                iou = [float((p & m).sum() / max((p | m).sum(), 1)) for p, m in zip(masks, oracle)]
                recall = [float((p & m).sum() / max(m.sum(), 1)) for p, m in zip(masks, oracle)]
                row[label] = {"iou_mean": float(np.mean(iou)), "iou_min": float(min(iou)),
                              "recall_mean": float(np.mean(recall)), "method_used": choice.method,
                              "exg_share": (choice.exg_pixels / choice.background_pixels
                                            if method == "auto" and choice.background_pixels else None),
                              "seconds_per_image": (time.perf_counter() - t0) / len(images)}
            cells[f"{plant}/{colour}"] = row
            print(plant, colour, {k: round(v["iou_mean"], 3) for k, v in row.items()}, flush=True)
    return cells


def real_cells(scan: Path, n_views: int, png: Path | None, threads: int) -> dict:
    """Each method's reconstruction of ``n_views`` evenly spaced images of a flight folder."""
    import dataclasses

    from bench.bench_real import clean_prior
    from vp_recon.flight import read_flight
    from vp_recon.segment import flight_masks
    from vp_recon.pipeline import Prior, ReconConfig, ReconError, crop_box, reconstruct_views

    views_all = read_flight(scan, max_megapixels=float("inf"))
    idx = np.round(np.arange(n_views) * len(views_all.names) / n_views).astype(int)
    sub = dataclasses.replace(views_all, names=[views_all.names[i] for i in idx],
                              images=[views_all.images[i] for i in idx],
                              reported=np.asarray(views_all.reported)[idx])
    out = {"images": list(sub.names)}
    shown, prior, look = {}, None, [0, len(idx) // 3, 2 * len(idx) // 3]
    for label, method, with_prior in REAL_METHODS:
        cfg = ReconConfig(width=sub.size[0], height=sub.size[1], fov=sub.horizontal_fov, mask=method,
                          num_threads=threads)
        t0 = time.perf_counter()
        try:
            vr = reconstruct_views(sub, cfg, prior=prior if with_prior else None)
            out[label] = {"registered": int(vr.sparse.registered), "sparse_points": len(vr.sparse.points),
                          "sparse_kept": len(vr.sparse_clean), "dense_points": len(vr.points),
                          "mask": vr.mask.to_dict() if vr.mask is not None else None}
            if label == "exg":  # the first pass: the prior of the +box rows
                pts = vr.points[clean_prior(vr.points)]
                prior = Prior(points=pts, plant=np.zeros(len(pts), np.int64))
                out["prior_points"] = len(pts)
        except ReconError as exc:
            out[label] = {"error": exc.name, "error_msg": str(exc)}
        out[label]["seconds"] = time.perf_counter() - t0
        print(label, out[label], flush=True)
        if png is not None:
            kw = dict(cameras=np.asarray(sub.reported)[look], K=sub.K,
                      box=crop_box(prior.points, cfg.crop_margin)) if with_prior and prior is not None else {}
            shown[label] = flight_masks([sub.images[i] for i in look], method, **kw)[0]
    if png is not None:
        import cv2

        rows = []
        for j, i in enumerate(look):
            tiles = [sub.images[i]] + [np.repeat(shown[m][j][..., None] * 255, 3, axis=2).astype(np.uint8)
                                       for m, _, _ in REAL_METHODS]
            rows.append(cv2.resize(np.concatenate(tiles, axis=1), ((1 + len(REAL_METHODS)) * 320, 240)))
        png.parent.mkdir(parents=True, exist_ok=True)
        cv2.imwrite(str(png), cv2.cvtColor(np.concatenate(rows), cv2.COLOR_RGB2BGR))
    return out


def markdown(data: dict) -> str:
    from bench.docs import num, table

    lines = ['# Plant masks', '', f'{data["width"]} x {data["height"]} renders of one plant over the soil with 4 '
             'ground markers and sensor noise, 8 ring views and a top view; IoU against the renderer\'s '
             'segmentation pass, mean (worst view). `auto+box` is what a reconstruction with a prior uses: '
             f'excess green when its pixels are at least {data["exg_share"]} of the background model\'s '
             '(share), else the background model.', '']
    body = []
    for cell, row in data['renders'].items():
        body.append([cell.replace('/', ' / ')] + [f'{num(row[m]["iou_mean"])} ({num(row[m]["iou_min"])})'
                                                   for m, _, _ in METHODS]
                    + [row['auto+box']['method_used'], num(row['auto+box']['exg_share'])])
    lines += table(['plant / colour'] + [m for m, _, _ in METHODS] + ['auto chose', 'share'], body)
    real = data.get('real')
    if real:
        lines += ['', f'Real scan `{data["scan"]}`: {len(real["images"])} evenly spaced images reconstructed with '
                  'each mask (no oracle: what the reconstruction keeps; `+box`: with the first pass of the `exg` row as the '
                  f'prior, {real.get("prior_points")} points).', '']
        body = []
        for m, _, _ in REAL_METHODS:
            r = real[m]
            body.append([m, r.get('error') or str(r['registered']), str(r.get('sparse_kept', '-')),
                         str(r.get('dense_points', '-')), (r.get('mask') or {}).get('method', '-')])
        lines += table(['mask', 'registered', 'sparse points kept', 'dense points', 'used'], body)
    return '\n'.join(lines) + '\n'


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--width', type=int, default=640)
    ap.add_argument('--height', type=int, default=480)
    ap.add_argument('--scan', type=Path, default=None, help='a flight folder of real photographs')
    ap.add_argument('--views', type=int, default=12, help='evenly spaced images of the scan reconstructed')
    ap.add_argument('--png', type=Path, default=None, help="the scan's masks of three views side by side")
    ap.add_argument('--threads', type=int, default=2)
    ap.add_argument('--out', type=Path, default=ROOT / 'results')
    args = ap.parse_args(argv)
    from vp_recon.segment import EXG_SHARE

    data = {'machine': machine(), 'date': time.strftime('%Y-%m-%d'), 'width': args.width, 'height': args.height,
            'exg_share': EXG_SHARE, 'renders': render_cells(args.width, args.height),
            'scan': args.scan.name if args.scan else None}
    if args.scan is not None:
        data['real'] = real_cells(args.scan, args.views, args.png, args.threads)
    write_report(args.out / 'masks.json', data)
    (args.out / 'masks.md').write_text(markdown(data))
    print(f'wrote {args.out / "masks.json"}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
