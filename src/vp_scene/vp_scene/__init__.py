"""vp_scene: the simulated world (paper Sec. V-A) and what every package shares.

The world (ROS-free): :mod:`vp_scene.plants` (the plant model), :mod:`vp_scene.ply` (PLY files,
checked), :mod:`vp_scene.procedural` (the built-in procedural corn), :mod:`vp_scene.layout`
(built-in layouts and layout files), :mod:`vp_scene.scenario` (plants placed after a layout),
:mod:`vp_scene.wind` (the paper's level-wise wind noise), :mod:`vp_scene.capture` (the capture
model), :mod:`vp_scene.meshing` and :mod:`vp_scene.render` (the plants rendered),
:mod:`vp_scene.sim_drone` (the simulated drones). Shared (ROS-free): :mod:`vp_scene.camera`,
:mod:`vp_scene.planfile`, :mod:`vp_scene.folders`, :mod:`vp_scene.images`, :mod:`vp_scene.cluster`.
ROS adapters (docs/CONTRACTS.md): :mod:`vp_scene.messages` (every ROS message conversion of the
suite), :mod:`vp_scene.cloud` (the PointCloud2 codec), :mod:`vp_scene.node_runtime` (parameters,
signals, exit codes of every node), and the nodes :mod:`vp_scene.scene_node` and
:mod:`vp_scene.sim_drone_node`.
"""
