"""vp_scene: noisy corn-field scenes (paper Sec. V-A).

ROS-free modules: :mod:`vp_scene.plants` (Corn50 PLY loading, procedural corn),
:mod:`vp_scene.scenario` (one_plant / three_row / six_rect layouts), :mod:`vp_scene.wind`
(the paper's level-wise wind noise). :mod:`vp_scene.cloud` converts to and from
``sensor_msgs/PointCloud2`` and :mod:`vp_scene.scene_node` is the ROS 2 node.
"""
