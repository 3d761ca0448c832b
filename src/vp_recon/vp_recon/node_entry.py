"""Console entry of the recon node (see :mod:`vp_scene.node_entry`)."""
from vp_scene.node_entry import start


def recon() -> int:
    return start("vp_recon.recon_node", preload=("pycolmap",))  # glog's SIGTERM handler: see node_entry
