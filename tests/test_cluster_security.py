"""Who can get into the suite's Dask clusters (Hardening III, items 1 and 2; README "Running the
benchmarks on a cluster").

- the local cluster (``open_client('local')``, what ``make run`` gives its recon node) listens on
  127.0.0.1 only, its dashboard included (it listened on all interfaces while the log said
  127.0.0.1), and the log names the address the dashboard really bound;
- it speaks TLS with this run's temporary credentials: a client without them (plain tcp, TLS
  without a certificate, another run's credentials) is refused within seconds; any local client
  ran code in the workers before (``Client(address).run(...)`` answered with their pid and uid);
- a remote cluster over TLS (a real ``dask scheduler`` and ``dask worker`` with a certificate made
  here, on 127.0.0.1): a client with the certificate files (``--tls-ca-file/--tls-cert/--tls-key``)
  runs tasks, one without them is refused; files that do not go with the address are one line.

Every wait has a deadline; the processes end in ``finally`` blocks or with the test.
"""
from __future__ import annotations

import datetime
import json
import os
import re
import socket
import ssl
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tools"))
from node_process import NodeProcess  # noqa: E402  (tools/node_process.py)

from vp_scene.cluster import TlsFiles, check_cluster_args, open_client  # noqa: E402

#: s a refused client may take (Dask's connect timeout given to it: 5 s)
REFUSED_WITHIN_S = 10.0


def tcp_listeners() -> set:
    """(ip, port) of the TCP sockets this process and its children listen on."""
    procs = [psutil.Process()] + psutil.Process().children(recursive=True)
    found = set()
    for proc in procs:
        try:
            conns = proc.net_connections(kind="tcp")
        except psutil.Error:  # a child that ended meanwhile
            continue
        found |= {(c.laddr.ip, c.laddr.port) for c in conns if c.status == psutil.CONN_LISTEN}
    return found


def test_the_local_cluster_listens_on_127_0_0_1_only_and_says_where(capfd) -> None:
    """Item 1: every socket the local cluster opens (scheduler, nanny, worker, their HTTP servers,
    the dashboard) is on 127.0.0.1, and the dashboard the log names is one of them."""
    before = tcp_listeners()
    with open_client("local", 1) as client:
        assert len(client.scheduler_info()["workers"]) == 1
        opened = tcp_listeners() - before
    err = capfd.readouterr().err
    assert len(opened) >= 4, opened  # scheduler, its dashboard, nanny, worker (and the worker's HTTP)
    assert {ip for ip, _ in opened} == {"127.0.0.1"}, f"listening beyond 127.0.0.1: {sorted(opened)}"
    said = re.search(r"dashboard http://([\d.]+):(\d+)/status", err)
    assert said, err
    assert (said.group(1), int(said.group(2))) in opened, (said.group(0), sorted(opened))


def test_the_local_cluster_refuses_clients_without_this_runs_credentials() -> None:
    """Item 2: the local scheduler ran any local client's code (``Client(addr).run(os.getuid)``);
    now it speaks TLS with credentials made for this run, and a client without them is refused:
    plain tcp, TLS without a client certificate, TLS with credentials of its own."""
    from distributed import Client, Security

    with open_client("local", 1, quiet=True) as client:
        address = client.scheduler.address
        assert client.run(os.getpid)  # the run's own client: its workers answer
        host, port = address.split("://")[1].rsplit(":", 1)
        times = {}
        for name, addr, security in (("tcp", address.replace("tls://", "tcp://"), None),
                                     ("other credentials", address.replace("tcp://", "tls://"), Security.temporary())):
            t0 = time.monotonic()
            with pytest.raises(OSError):  # refused (CommClosedError is an OSError)
                intruder = Client(addr, timeout="5s", security=security)
                intruder.run(os.getuid)  # not reached on a refused connection
            times[name] = time.monotonic() - t0
        ctx = ssl.create_default_context()
        ctx.check_hostname, ctx.verify_mode = False, ssl.CERT_NONE  # no certificate of its own
        t0 = time.monotonic()
        with socket.create_connection((host, int(port)), timeout=5) as raw:
            with pytest.raises((ssl.SSLError, ConnectionError)):
                with ctx.wrap_socket(raw) as tls:  # TLS 1.3: the refusal comes with the first read
                    tls.sendall(b"\0" * 16)
                    if not tls.recv(16):
                        raise ConnectionError("closed")
        times["no certificate"] = time.monotonic() - t0
    assert address.startswith("tls://127.0.0.1:"), address
    assert max(times.values()) < REFUSED_WITHIN_S, times
    print(f"\nrefused in {', '.join(f'{k} {v:.2f} s' for k, v in times.items())}")


def make_certificate(folder: Path) -> TlsFiles:
    """One self-signed certificate (with its key) for the whole cluster, as README's openssl line
    makes: every party presents it and trusts it as the CA."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import rsa
    from cryptography.x509.oid import NameOID

    key = rsa.generate_private_key(public_exponent=65537, key_size=2048)
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "vp-cluster")])
    now = datetime.datetime.now(datetime.timezone.utc)
    cert = (x509.CertificateBuilder().subject_name(name).issuer_name(name).public_key(key.public_key())
            .serial_number(x509.random_serial_number()).not_valid_before(now - datetime.timedelta(minutes=5))
            .not_valid_after(now + datetime.timedelta(days=1))
            .add_extension(x509.BasicConstraints(ca=True, path_length=None), critical=True)
            .sign(key, hashes.SHA256()))
    cert_path, key_path = folder / "cluster.pem", folder / "cluster-key.pem"
    cert_path.write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    key_path.write_bytes(key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                           serialization.NoEncryption()))
    key_path.chmod(0o600)
    return TlsFiles(str(cert_path), str(cert_path), str(key_path))


def scheduler_address(info: Path, scheduler: NodeProcess, timeout: float) -> str:
    """The address in a ``dask scheduler --scheduler-file`` once the file holds it whole (dask
    writes it in place: a reader may see it empty or cut)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and scheduler.alive():
        try:
            return json.loads(info.read_text())["address"]
        except (OSError, ValueError, KeyError):  # not there yet, or not written whole
            time.sleep(0.1)
    raise AssertionError(f"no address in {info} after {timeout:.0f} s:\n{scheduler.output()[-2000:]}")


def test_a_tls_cluster_serves_the_client_with_the_certificate_and_refuses_others(tmp_path, capfd) -> None:
    """Item 2, a cluster of your own machines: ``dask scheduler --protocol tls`` and ``dask worker``
    with the certificate (README's commands, on 127.0.0.1); ``open_client('tls://...', tls=...)``,
    what ``--scheduler tls://... --tls-ca-file ... --tls-cert ... --tls-key ...`` gives, runs a task;
    a client without the certificate is refused."""
    from distributed import Client, Security

    tls = make_certificate(tmp_path)
    files = ["--tls-ca-file", tls.ca_file, "--tls-cert", tls.cert, "--tls-key", tls.key]
    dask = str(Path(sys.executable).with_name("dask"))
    env = {k: v for k, v in os.environ.items() if not k.startswith("DASK_")}
    info = tmp_path / "scheduler.json"
    procs = [NodeProcess([dask, "scheduler", "--protocol", "tls", "--host", "127.0.0.1", "--port", "0",
                          "--no-dashboard", "--scheduler-file", str(info), *files], env, tmp_path / "scheduler.log")]
    try:
        address = scheduler_address(info, procs[0], 60)
        assert address.startswith("tls://127.0.0.1:"), address
        procs.append(NodeProcess([dask, "worker", address, "--host", "127.0.0.1", "--nthreads", "1", "--no-nanny",
                                  "--no-dashboard", "--name", "w0", *files], env, tmp_path / "worker.log"))
        with open_client(address, tls=tls) as client:
            client.wait_for_workers(1, timeout=60)
            assert client.submit(pow, 2, 10).result(timeout=60) == 1024
        assert f"dask: {address}, " in capfd.readouterr().err
        # the same files through dask's own config, as environment variables (DASK_SCHEDULER_ADDRESS too)
        tls_env = {**env, "DASK_SCHEDULER_ADDRESS": address, "DASK_DISTRIBUTED__COMM__TLS__CA_FILE": tls.ca_file,
                   "DASK_DISTRIBUTED__COMM__TLS__CLIENT__CERT": tls.cert,
                   "DASK_DISTRIBUTED__COMM__TLS__CLIENT__KEY": tls.key}
        code = ("from vp_scene.cluster import open_client\n"
                "with open_client(quiet=True) as c:\n    print(c.submit(pow, 3, 4).result(timeout=60))")
        done = subprocess.run([sys.executable, "-c", code], env=tls_env, capture_output=True, text=True, timeout=120)
        assert done.returncode == 0 and done.stdout.strip() == "81", done.stderr[-2000:]
        for addr, security in ((address.replace("tls://", "tcp://"), None), (address, Security.temporary())):
            t0 = time.monotonic()
            with pytest.raises(OSError):
                Client(addr, timeout="5s", security=security).run(os.getuid)
            assert time.monotonic() - t0 < REFUSED_WITHIN_S
        with pytest.raises(ValueError, match="is tls://: give the CA file"):  # no certificate: said at once
            with open_client(address):
                pass
        assert all(p.alive() for p in procs), [p.output()[-1500:] for p in procs]
    finally:
        for proc in reversed(procs):
            proc.stop()


def test_tls_files_that_do_not_go_with_the_address_are_one_line(tmp_path) -> None:
    """Certificate files for 'local' or a tcp:// address, a missing file, a tls:// address without
    files: ValueError in the engine, ``<prog>: error: ...`` and exit 2 in the CLIs (the recon
    node's parameters: the same check, exit 2 at start)."""
    pem = tmp_path / "c.pem"
    pem.write_text("x")
    cases = [("local", TlsFiles(str(pem), str(pem)), "the local cluster makes its own"),
             ("tcp://127.0.0.1:8786", TlsFiles(str(pem), str(pem)), "for a tls:// scheduler address"),
             ("tls://127.0.0.1:8786", TlsFiles(str(pem), str(tmp_path / "none.pem")), "none.pem: no such file"),
             ("tls://127.0.0.1:8786", TlsFiles(cert=str(pem)), "the CA file and the certificate"),
             ("tls://127.0.0.1:8786", TlsFiles(), "is tls://: give the CA file")]
    for scheduler, tls, said in cases:
        with pytest.raises(ValueError, match=said):
            check_cluster_args(scheduler, 1, tls)
    env = {k: v for k, v in os.environ.items() if not k.startswith("DASK_")}
    for cmd, prog in (([sys.executable, str(REPO / "bench" / "table1.py")], "table1.py"),
                      ([sys.executable, "-m", "vp_recon.cli", "--plan", str(pem)], "recon")):
        done = subprocess.run(cmd + ["--scheduler", "tls://127.0.0.1:8786", "--out", str(tmp_path / "out")],
                              capture_output=True, text=True, timeout=120, env=env)
        lines = done.stderr.strip().splitlines()
        assert done.returncode == 2 and len(lines) >= 1, done.stderr[-2000:]
        assert lines[-1].startswith(prog) and "error: scheduler tls://127.0.0.1:8786 is tls://" in lines[-1], lines
    from vp_recon.recon_node import check_parameters

    with pytest.raises(ValueError, match="go with a scheduler"):
        check_parameters({"tls_ca_file": str(pem)})
    with pytest.raises(ValueError, match="is tls://: give the CA file"):
        check_parameters({"scheduler": "tls://127.0.0.1:8786"})
    assert check_parameters({"scheduler": "tls://127.0.0.1:8786", "tls_ca_file": str(pem), "tls_cert": str(pem)})
