"""vp_planner: EGP-VP view planning (Bacharis et al.): reward, search space, optimizers, poses.

The ROS-free library lives in submodules (``reward``, ``space``, ``bo``, ``optimizers``,
``poses``, ``cli``); they are imported on demand so that ``import vp_planner`` stays cheap.
"""

__version__ = "0.1.0"
