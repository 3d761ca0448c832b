"""The cluster engine across hosts: a `dask scheduler` in one network namespace, a `dask worker`
in each of two others (the lab of tests/test_across_hosts.py: a bridge with no uplink, no route
out, torn down also on failure; skipped with its reason where namespaces cannot be made). A
Table I slice run from a client beside the scheduler gives the records of the in-process run."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "bench"))
sys.path.insert(0, str(REPO / "tests"))
from test_across_hosts import lab  # noqa: E402,F401  (the fixture: namespaces, bridge, teardown)
from test_cluster import _in_process, _slice_args, _without_times  # noqa: E402

PORT = 8786
CLIENT = """
import json, sys
sys.path.insert(0, {bench!r})
import table1
from cluster import open_client
args = table1.parse_args({argv!r})
with open_client(args.scheduler, quiet=True) as client:
    client.wait_for_workers(2, timeout=180)  # both hosts' workers, bounded
    plans, recons = table1.run(args, client)
open({out!r}, 'w').write(json.dumps({{'plans': [[list(k), v] for k, v in plans.items()],
                                      'recons': [[list(k), v] for k, v in recons.items()]}}))
"""


def test_table1_slice_on_a_scheduler_and_two_workers_in_namespaces(lab, tmp_path, monkeypatch):  # noqa: F811
    monkeypatch.setenv("PYOPENGL_PLATFORM", "egl")
    plans, recons = _in_process(_slice_args(tmp_path / "inproc", 1))
    ref = _without_times((plans, recons))

    env = dict(os.environ, PYOPENGL_PLATFORM="egl", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1",
               OPENBLAS_NUM_THREADS="1", DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT="30s",
               PYTHONPATH=os.pathsep.join([str(REPO / "bench"), os.environ.get("PYTHONPATH", "")]))
    env.pop("DASK_SCHEDULER_ADDRESS", None)
    sched = f"tcp://{lab.addr['scene']}:{PORT}"
    dask = str(Path(sys.executable).with_name("dask"))
    lab.start("scene", "scheduler", [dask, "scheduler", "--host", lab.addr["scene"], "--port", str(PORT),
                                     "--no-dashboard"], env)
    for host in ("planner", "recon"):
        lab.start(host, "worker", [dask, "worker", sched, "--host", lab.addr[host], "--nthreads", "1",
                                   "--nworkers", "1", "--no-dashboard", "--name", host], env)
    out = tmp_path / "client.json"
    argv = ["--models", "", "--scenarios", "one_plant", "--rows", "circle", "arc", "--seeds", "1", "--evals", "4",
            "--init", "2", "--width", "1000", "--height", "750", "--realizations", "1", "--threads", "1", "--capture", "ideal",
            "--scheduler", sched, "--out", str(tmp_path / "client")]
    code = CLIENT.format(bench=str(REPO / "bench"), argv=argv, out=str(out))
    res = subprocess.run(["ip", "netns", "exec", lab.ns["scene"], sys.executable, "-c", code], env=env,
                         capture_output=True, text=True, timeout=480)
    assert res.returncode == 0, res.stderr[-3000:]
    got = json.loads(out.read_text())
    got = ({tuple(k): v for k, v in got["plans"]}, {tuple(k): v for k, v in got["recons"]})
    assert _without_times(got) == ref
