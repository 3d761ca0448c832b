"""vp_scene: noisy corn-field scenes (paper Sec. V-A).

ROS-free modules: :mod:`vp_scene.plants` (Corn50 PLY loading, procedural corn),
:mod:`vp_scene.layout` (built-in layouts and layout files), :mod:`vp_scene.scenario` (plants
placed after a layout), :mod:`vp_scene.wind`
(the paper's level-wise wind noise). :mod:`vp_scene.cloud` converts to and from
``sensor_msgs/PointCloud2`` and :mod:`vp_scene.scene_node` is the ROS 2 node.
"""
