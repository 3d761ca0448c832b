"""The cluster engine across hosts: a `dask scheduler` in one network namespace, a `dask worker`
in each of two others (the lab of tests/test_across_hosts.py: a bridge with no uplink, no route
out, torn down also on failure; skipped with its reason where namespaces cannot be made). A
Table I slice run from a client beside the scheduler gives the records of the in-process run; a
worker SIGKILLed in its namespace mid-run loses no task."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from test_across_hosts import lab  # noqa: F401  (the fixture: namespaces, bridge, teardown; tests/ is on sys.path)
from test_cluster import SLICE_ARGV, _in_process, _slice_args, _without_times

REPO = Path(__file__).resolve().parents[1]

PORT = 8786
CLIENT = """
import json
from bench import table1
from bench.cluster import open_client
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
               PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]))
    env.pop("DASK_SCHEDULER_ADDRESS", None)
    sched = f"tcp://{lab.addr['scene']}:{PORT}"
    dask = str(Path(sys.executable).with_name("dask"))
    lab.start("scene", "scheduler", [dask, "scheduler", "--host", lab.addr["scene"], "--port", str(PORT),
                                     "--no-dashboard"], env)
    for host in ("planner", "recon"):
        lab.start(host, "worker", [dask, "worker", sched, "--host", lab.addr[host], "--nthreads", "1",
                                   "--nworkers", "1", "--no-dashboard", "--name", host], env)
    out = tmp_path / "client.json"
    argv = [*SLICE_ARGV, "--scheduler", sched, "--out", str(tmp_path / "client")]
    code = CLIENT.format(argv=argv, out=str(out))
    res = subprocess.run(["ip", "netns", "exec", lab.ns["scene"], sys.executable, "-c", code], env=env,
                         capture_output=True, text=True, timeout=480)
    assert res.returncode == 0, res.stderr[-3000:]
    got = json.loads(out.read_text())
    got = ({tuple(k): v for k, v in got["plans"]}, {tuple(k): v for k, v in got["recons"]})
    assert _without_times(got) == ref


KILL_CLIENT = """
import glob, json, os, signal, threading, time
from bench import cluster

def held_square(x, folder):
    # marks its start, then waits for the test's release: a worker killed meanwhile dies mid-task
    import os, time
    open(os.path.join(folder, f'started-{{os.getpid()}}-{{x}}'), 'w').close()
    deadline = time.monotonic() + 120
    while not os.path.exists(os.path.join(folder, 'release')) and time.monotonic() < deadline:
        time.sleep(0.02)
    return {{'x': x, 'square': x * x, 'pid': os.getpid()}}

with cluster.open_client({sched!r}, quiet=True) as client:
    client.wait_for_workers(2, timeout=180)
    pids = client.run(os.getpid)  # worker address -> pid (one pid namespace: the lab's are network ones)
    victim = pids[next(a for a in pids if {victim_addr!r} in a)]
    killed = []

    def kill_mid_task():
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:  # the victim has started a task, which waits for us
            if glob.glob(os.path.join({folder!r}, f'started-{{victim}}-*')):
                os.kill(victim, signal.SIGKILL)
                killed.append(victim)
                break
            time.sleep(0.05)
        open(os.path.join({folder!r}, 'release'), 'w').close()

    killer = threading.Thread(target=kill_mid_task, daemon=True)
    killer.start()
    tasks = [cluster.Task(i, held_square, (i, {folder!r})) for i in range(12)]
    rec = cluster.run_tasks(client, tasks, timeout=300)
    killer.join(timeout=70)
    left = len(client.scheduler_info()['workers'])
open({out!r}, 'w').write(json.dumps({{'killed': killed, 'victim': victim, 'left': left,
                                      'records': [[k, v] for k, v in rec.items()]}}))
"""


def test_a_worker_killed_in_its_namespace_loses_no_task(lab, tmp_path):  # noqa: F811
    """Issue 22, item 2: the worker of one host SIGKILLed mid-run (no nanny to restart it): the
    scheduler reruns its tasks on the other host's worker; every task has its result."""
    env = dict(os.environ, OMP_NUM_THREADS="1", DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT="30s",
               PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]))
    env.pop("DASK_SCHEDULER_ADDRESS", None)
    sched = f"tcp://{lab.addr['scene']}:{PORT}"
    dask = str(Path(sys.executable).with_name("dask"))
    lab.start("scene", "scheduler", [dask, "scheduler", "--host", lab.addr["scene"], "--port", str(PORT),
                                     "--no-dashboard"], env)
    for host in ("planner", "recon"):
        lab.start(host, "worker", [dask, "worker", sched, "--host", lab.addr[host], "--nthreads", "1",
                                   "--no-nanny", "--no-dashboard", "--name", host], env)
    out = tmp_path / "kill.json"
    held = tmp_path / "held"
    held.mkdir()
    code = KILL_CLIENT.format(sched=sched, victim_addr=lab.addr["recon"], out=str(out), folder=str(held))
    res = subprocess.run(["ip", "netns", "exec", lab.ns["scene"], sys.executable, "-c", code], env=env,
                         capture_output=True, text=True, timeout=420)
    assert res.returncode == 0, res.stderr[-3000:]
    got = json.loads(out.read_text())
    assert got["killed"] == [got["victim"]] and got["left"] == 1  # the recon host's worker is gone
    rec = {k: v for k, v in got["records"]}
    assert sorted(rec) == list(range(12))
    assert all("error" not in r and r["square"] == i * i for i, r in rec.items()), rec
    assert all(r["pid"] != got["victim"] for r in rec.values())  # its task ran again on the other host
