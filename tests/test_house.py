"""The house (issue 39, item 3): three rooms that layer (vp_scene, the simulated world and what every
package shares, below; vp_planner and vp_recon beside each other on it), one home per concept, no
import cycle, no re-export, and the ROS adapters docs/CONTRACTS.md names are exactly the modules
that import ROS. The static checks read the sources (lazy imports inside functions included); the
ROS check imports every module in a fresh interpreter with rclpy and the message packages blocked."""
from __future__ import annotations

import ast
import importlib
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("vp_scene", "vp_planner", "vp_recon")
#: what each package may import of the others
MAY_IMPORT = {"vp_scene": set(), "vp_planner": {"vp_scene"}, "vp_recon": {"vp_scene"}}


def modules() -> dict:
    """{'pkg.module': path} of the three packages' modules."""
    return {f"{pkg}.{f.stem}": f for pkg in PACKAGES for f in sorted((ROOT / "src" / pkg / pkg).glob("*.py"))
            if f.stem != "__init__"}


def imported(name: str, path: Path) -> set:
    """The suite modules (or packages) ``name`` imports anywhere in its source."""
    pkg, out = name.split(".")[0], set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            base = (pkg + ("." + node.module if node.module else "")) if node.level else (node.module or "")
            out.add(base)
            out.update(f"{base}.{a.name}" for a in node.names)
        elif isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
    return {m for m in out if m.split(".")[0] in PACKAGES} - {name}


def test_the_packages_layer() -> None:
    """vp_planner depended on all of vp_recon for its simulated drone's rendering (sim_drone_node)
    and its CLI's result folder; the world and the shared pieces now live in vp_scene."""
    wrong = sorted(f"{name} imports {m}" for name, path in modules().items() for m in imported(name, path)
                   if m.split(".")[0] != name.split(".")[0] and m.split(".")[0] not in MAY_IMPORT[name.split(".")[0]])
    assert not wrong, wrong
    for pkg in PACKAGES:
        deps = set(re.findall(r"<exec_depend>(vp_\w+)</exec_depend>", (ROOT / "src" / pkg / "package.xml").read_text()))
        assert deps - {"vp_interfaces"} == MAY_IMPORT[pkg], (pkg, deps)


def test_no_module_imports_one_that_imports_it_back() -> None:
    """space.py and designs.py imported each other, pipeline.py and flight.py too (lazily)."""
    mods = modules()
    graph = {name: {m for m in imported(name, path) if m in mods} for name, path in mods.items()}
    cycles, state = [], {}

    def visit(v: str, stack: list) -> None:
        state[v] = "open"
        for w in sorted(graph[v]):
            if state.get(w) == "open":
                cycles.append(stack[stack.index(w):] + [w])
            elif w not in state:
                visit(w, stack + [w])
        state[v] = "done"

    for v in sorted(graph):
        if v not in state:
            visit(v, [v])
    assert not cycles, cycles


def test_a_module_exports_only_what_it_defines() -> None:
    """optimizers.py re-exported 29 names of other rooms (the benchmarks imported PlanRequest from
    it); a name is imported from its home."""
    found = []
    for name, path in modules().items():
        tree = ast.parse(path.read_text())
        defined, exported = set(), []
        for node in tree.body:
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                defined.add(node.name)
            elif isinstance(node, (ast.Assign, ast.AnnAssign)):
                targets = node.targets if isinstance(node, ast.Assign) else [node.target]
                defined.update(n.id for t in targets for n in ast.walk(t) if isinstance(n, ast.Name))
                if any(isinstance(t, ast.Name) and t.id == "__all__" for t in targets):
                    exported = [e.value for e in node.value.elts]
        found += [f"{name}.{n}" for n in exported if n not in defined]
    assert not found, found


#: One home per concept: where each lives (its __module__), after the rooms of issue 39, item 3.
HOMES = {
    "vp_scene.camera": ["direction", "azimuth_elevation"],
    "vp_scene.sim_drone": ["fly_toward", "photograph", "Photographs"],
    "vp_scene.render": ["Renderer", "RenderError"],
    "vp_scene.meshing": ["scene_meshes"],
    "vp_scene.folders": ["ResultFolder", "new_run_folder", "move_aside", "FolderLock"],
    "vp_planner.designs": ["random_plans", "structured_plans"],
    "vp_recon.errors": ["ReconError", "validate_cameras", "check_plan_size", "ensure_writable_dir"],
    "vp_recon.config": ["ReconConfig", "matching_method"],
    "vp_recon.results": ["RealizationResult", "PlanReconResult", "ViewsResult", "Prior", "plan_result"],
    "vp_recon.progress": ["ReconCancelled", "tick"],
    "vp_recon.tasks": ["worker_call", "worker_result", "ClusterQueue"],
    "vp_recon.pipeline": ["render_flight", "reconstruct_views", "reconstruct_set", "reconstruct_sets",
                          "reconstruct_plan"],
    "vp_recon.segment": ["plant_mask", "image_mask"],
    "vp_recon.fleet_captures": ["FleetCaptures"],
}


@pytest.mark.parametrize("home", sorted(HOMES))
def test_one_home_per_concept(home: str) -> None:
    module = importlib.import_module(home)
    assert [n for n in HOMES[home] if getattr(module, n).__module__ != home] == []


BLOCK_ROS = """
import importlib, importlib.abc, json, pkgutil, sys

def ros(name):
    top = name.split('.')[0]
    return top.startswith(('rclpy', 'rcl_', 'rosidl', 'rosbag2', 'ament_', 'tf2', 'rpyutils')) or \\
        top.endswith(('_msgs', '_interfaces'))

class Block(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if ros(name):
            raise ImportError(f'ROS module {name} blocked')

sys.meta_path.insert(0, Block())
failed = {}
for pkg in sys.argv[1:]:
    for m in pkgutil.iter_modules(importlib.import_module(pkg).__path__):
        try:
            importlib.import_module(f'{pkg}.{m.name}')
        except ImportError as exc:
            failed[f'{pkg}.{m.name}'] = str(exc)
print(json.dumps(failed))
"""


def test_the_ros_adapters_are_the_ones_the_contracts_name() -> None:
    """docs/CONTRACTS.md called vp_scene ROS-free while it held messages, cloud and node_runtime:
    it now names the ROS adapters, and every other module imports without ROS."""
    text = (ROOT / "docs" / "CONTRACTS.md").read_text()
    section = text.split("except these ROS adapters:", 1)
    assert len(section) == 2, "docs/CONTRACTS.md names no ROS adapters"
    named = set(re.findall(r"`(vp_\w+\.\w+)`", section[1].split("\n\n", 1)[0]))
    out = subprocess.run([sys.executable, "-c", BLOCK_ROS, *PACKAGES], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    failed = json.loads(out.stdout.strip().splitlines()[-1])
    assert all("blocked" in why for why in failed.values()), failed
    assert set(failed) == named, {"import ROS, not named": sorted(set(failed) - named),
                                  "named, ROS-free": sorted(named - set(failed))}


def test_the_development_guide_names_every_room() -> None:
    """docs/development.md's table of the house names each package's modules, and none of another
    package's."""
    guide = (ROOT / "docs" / "development.md").read_text()
    for pkg in PACKAGES:
        rows = [line for line in guide.splitlines() if line.startswith(f"| `{pkg}`")]
        assert rows, pkg
        named = set(re.findall(r"`(\w+)`", " ".join(r.split("|")[2] for r in rows)))
        have = {name.split(".")[1] for name in modules() if name.startswith(pkg + ".")}
        assert have - named == set(), (pkg, "not in docs/development.md", sorted(have - named))
        elsewhere = {name.split(".")[1] for name in modules() if not name.startswith(pkg + ".")} - have
        assert named & elsewhere == set(), (pkg, "named, but another package's", sorted(named & elsewhere))
