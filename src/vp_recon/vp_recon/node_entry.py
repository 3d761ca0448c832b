"""Console entries of the recon, recorder and viewer nodes (see :mod:`vp_scene.node_entry`)."""
from vp_scene.node_entry import start


def recon() -> int:
    return start("vp_recon.recon_node", preload=("pycolmap",))  # glog's SIGTERM handler: see node_entry


def recorder() -> int:
    return start("vp_recon.recorder_node")


def viewer() -> int:
    return start("vp_recon.viewer_node")
