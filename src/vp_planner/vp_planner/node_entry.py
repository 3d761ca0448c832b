"""Console entries of the planner package's nodes (see :mod:`vp_scene.node_entry`)."""
from vp_scene.node_entry import start


def planner() -> int:
    return start("vp_planner.planner_node")


def dispatcher() -> int:
    return start("vp_planner.dispatcher_node")
