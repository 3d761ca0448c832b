"""vp_scene: noisy corn-field scenes (paper Sec. V-A).

ROS-free modules: :mod:`vp_scene.plants` (the plant model), :mod:`vp_scene.ply` (PLY files,
checked), :mod:`vp_scene.procedural` (the built-in procedural corn), :mod:`vp_scene.layout`
(built-in layouts and layout files), :mod:`vp_scene.scenario` (plants placed after a layout),
:mod:`vp_scene.wind` (the paper's level-wise wind noise). ROS glue: :mod:`vp_scene.messages`
(every ROS message conversion of the suite; :mod:`vp_scene.cloud` is its PointCloud2 codec),
:mod:`vp_scene.node_runtime` (parameters, signals, exit codes of every node) and
:mod:`vp_scene.scene_node`, the ROS 2 node.
"""
