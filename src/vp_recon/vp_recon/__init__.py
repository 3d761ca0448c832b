"""vp_recon: reconstruct a flight's images and score the reconstruction (paper Sec. V-B).

ROS-free modules (import cost is paid per module, nothing heavy is imported here):
:mod:`vp_recon.config` (ReconConfig and its caps), :mod:`vp_recon.errors` (the error codes,
ReconError, the input checks), :mod:`vp_recon.results` (what a reconstruction gives),
:mod:`vp_recon.progress` (stages, cancel), :mod:`vp_recon.pipeline` (the one loop over capture
sets, reconstruct_sets; render_flight, reconstruct_views, reconstruct_plan), :mod:`vp_recon.tasks`
(Dask tasks), :mod:`vp_recon.segment` (plant masks), :mod:`vp_recon.sparse` (pycolmap SIFT and the
sparse model, with :mod:`vp_recon.colmap_io`, :mod:`vp_recon.sparse_modes` and
:mod:`vp_recon.registration`), :mod:`vp_recon.dense` (SGBM
stereo on the CPU), :mod:`vp_recon.metrics` (Chamfer, F-score), :mod:`vp_recon.outputs` (PLY,
contact sheet, recon.json) and :mod:`vp_recon.cli`. The rendering of a plan is the simulated
world's (:mod:`vp_scene.render`, :mod:`vp_scene.sim_drone`). :mod:`vp_recon.recon_node` (with
:mod:`vp_recon.fleet_captures`) is the ROS 2 node.
"""
