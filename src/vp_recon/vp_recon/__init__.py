"""vp_recon: render planned views, reconstruct them and score the reconstruction (paper Sec. V-B).

ROS-free modules (import cost is paid per module, nothing heavy is imported here):
:mod:`vp_recon.render` (camera model, pyrender), :mod:`vp_recon.meshing` (plant meshes per wind
realization), :mod:`vp_recon.sparse` (pycolmap SIFT + triangulation), :mod:`vp_recon.dense`
(SGBM stereo on the CPU), :mod:`vp_recon.metrics` (Chamfer, F-score), :mod:`vp_recon.pipeline`
(ReconConfig, reconstruct_realization, reconstruct_plan, error codes), :mod:`vp_recon.outputs`
(PLY, contact sheet, recon.json) and :mod:`vp_recon.cli`. :mod:`vp_recon.recon_node` is the ROS 2 node.
"""
