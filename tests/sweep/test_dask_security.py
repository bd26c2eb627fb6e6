"""twin.jobs.cluster on real Dask: a local cluster that only this process's client can use (TLS
with a throwaway certificate; a foreign client, plain or with its own certificate, is refused) and
that serves no HTTP unless asked; connect() failing in bounded time on a port that is not Dask's;
and a cluster secured with the user's own certificates (`dask scheduler` / `dask worker` with
--tls-*) reached through Dask's configuration in environment variables."""

from __future__ import annotations

import asyncio
import datetime
import ipaddress
import json
import os
import socket
import ssl
import subprocess
import sys
import threading
import time
import urllib.request

import psutil
import pytest
from distributed import Client
from distributed.comm import connect as comm_connect
from distributed.core import send_recv
from distributed.security import Security

from twin.jobs.cluster import connect, start_local
from twin.model.errors import ConfigError

# Dask's default HTTP port: its scheduler served /metrics, /health, /info there
DASHBOARD_PORT = 8787


def _listening(pid: int) -> set[int]:
    return {
        c.laddr.port
        for c in psutil.Process(pid).net_connections(kind="inet")
        if c.status == psutil.CONN_LISTEN
    }


def _port(address: str) -> int:
    return int(address.rsplit(":", 1)[1])


@pytest.fixture(scope="module")
def local():
    """start_local(2) without a dashboard, with this process's listening ports from before it."""
    before = _listening(os.getpid())
    cluster, client, url = start_local(2, preload=())
    try:
        yield {"cluster": cluster, "client": client, "url": url, "before": before}
    finally:
        client.close()
        cluster.close()


def _refused(address: str, **connection_args) -> str:
    """Connect to a Dask server and ask who it is, as a foreign process would: the error text (the
    test fails if it answers)."""

    async def ask():
        comm = await comm_connect(address, timeout=3, **connection_args)
        try:
            return await send_recv(comm, op="identity")
        finally:
            comm.abort()

    try:
        answer = asyncio.run(asyncio.wait_for(ask(), 5))
    except (OSError, TimeoutError) as err:
        return f"{type(err).__name__}: {err}"
    raise AssertionError(f"{address} answered a foreign client: {answer}")


def test_only_the_clusters_own_client_gets_in(local):
    cluster, client = local["cluster"], local["client"]
    address = cluster.scheduler_address
    assert address.startswith("tls://127.0.0.1:")
    assert cluster.security.require_encryption
    # the cluster's own client runs a task
    assert client.submit(lambda x: x * 2, 21).result(timeout=30) == 42

    plain = "tcp://" + address.removeprefix("tls://")
    stranger = Security.temporary()  # a certificate of its own: a different CA
    for label, target, kwargs in (
        ("plain tcp", plain, {}),
        ("own Security.temporary()", address, {"security": stranger}),
    ):
        start = time.monotonic()
        # CommClosedError (reset by the TLS server), FatalCommClosedError (certificate)
        with pytest.raises(OSError):
            Client(target, timeout=3, set_as_default=False, **kwargs)
        assert time.monotonic() - start < 5, label

    nannies = [w.address for w in cluster.workers.values()]
    workers = list(client.scheduler_info()["workers"])
    assert len(nannies) == len(workers) == 2
    # not one of the cluster's servers answers a stranger
    for target in [address, *nannies, *workers]:
        assert target.startswith("tls://127.0.0.1:")
        _refused("tcp://" + target.removeprefix("tls://"))
        assert "TLS" in _refused(target, **stranger.get_connection_args("client"))


def test_no_http_server_unless_asked(local):
    cluster, client = local["cluster"], local["client"]
    assert local["url"] is None
    info = client.scheduler_info()
    assert info["services"] == {}  # no "dashboard": no HTTP server on the scheduler
    assert all(w["services"] == {} for w in info["workers"].values())
    # this process: the scheduler's and the nannies' comm ports, nothing else
    ours = {_port(cluster.scheduler_address), *(_port(w.address) for w in cluster.workers.values())}
    assert _listening(os.getpid()) - local["before"] == ours
    for address, pid in client.run(os.getpid).items():  # each worker process: its comm port alone
        assert _listening(pid) == {_port(address)}
    assert DASHBOARD_PORT not in ours


def test_the_dashboard_when_asked_is_on_loopback_on_a_free_port():
    cluster, client, url = start_local(1, dashboard=True, preload=())
    try:
        assert url.startswith("http://127.0.0.1:") and url.endswith("/status")
        port = int(url.split(":")[2].split("/")[0])
        assert port != DASHBOARD_PORT and port in _listening(os.getpid())
        with urllib.request.urlopen(url, timeout=5) as answer:
            assert answer.status == 200
        for address, pid in client.run(os.getpid).items():  # the workers still serve no HTTP
            assert _listening(pid) == {_port(address)}
    finally:
        client.close()
        cluster.close()


def _worker_state(dask_worker):
    import dask

    return (
        os.getpid(),
        type(dask_worker).__name__,
        dask_worker.services,
        dask.config.get("distributed.worker.profile.enabled"),
        os.environ.get("OMP_NUM_THREADS"),
    )


def test_a_worker_the_nanny_restarts_is_the_same():
    """Killed, a worker process is started again by its nanny: still TLS, no HTTP server, the
    configuration start_local set (a nanny's copy of it was reverted with dask.config.set's
    context)."""
    cluster, client, _ = start_local(1, preload=())
    try:
        (first,) = client.run(_worker_state).values()
        assert first[1:] == ("QuietWorker", {}, False, "1")
        psutil.Process(first[0]).kill()
        deadline = time.monotonic() + 30
        while True:
            time.sleep(0.2)
            states = client.run(_worker_state)
            if len(states) == 1 and next(iter(states.values()))[0] != first[0]:
                break
            assert time.monotonic() < deadline, "the nanny did not restart its worker"
        ((address, again),) = states.items()
        assert address.startswith("tls://127.0.0.1:")
        assert again[1:] == ("QuietWorker", {}, False, "1")
        assert _listening(again[0]) == {_port(address)}
    finally:
        client.close()
        cluster.close()


@pytest.fixture
def mute_port():
    """A TCP port that accepts connections and never answers, or answers bytes that are not
    Dask's."""
    servers = []

    def make(answer: bytes = b"") -> str:
        srv = socket.socket()
        srv.bind(("127.0.0.1", 0))
        srv.listen(8)
        servers.append(srv)

        def serve():
            while True:
                try:
                    conn, _ = srv.accept()
                except OSError:
                    return
                servers.append(conn)
                if answer:
                    conn.sendall(answer)

        threading.Thread(target=serve, daemon=True).start()
        return f"tcp://127.0.0.1:{srv.getsockname()[1]}"

    yield make
    for s in servers:
        s.close()


def test_connect_to_a_port_that_never_answers_fails_within_bounds(mute_port):
    address = mute_port()
    start = time.monotonic()
    with pytest.raises(ConfigError) as err:
        connect(address)  # the default 10 s: Client(timeout=10) waited here for ever
    assert time.monotonic() - start < 15
    text = str(err.value)
    assert "\n" not in text and address in text and "did not answer Dask's handshake" in text


@pytest.mark.parametrize(
    "answer",
    [b"HTTP/1.0 200 OK\r\n\r\nhello" * 10, (1 << 20).to_bytes(8, "little")],
    ids=["junk", "a length, then nothing"],
)
def test_connect_to_a_port_that_speaks_something_else_fails_within_bounds(mute_port, answer):
    address = mute_port(answer)
    start = time.monotonic()
    with pytest.raises(ConfigError, match="cannot reach the Dask scheduler") as err:
        connect(address, timeout_s=2)
    assert time.monotonic() - start < 6
    assert "\n" not in str(err.value) and address in str(err.value)


def test_connect_to_a_zeromq_socket_fails_within_bounds():
    zmq = pytest.importorskip("zmq")
    ctx = zmq.Context()
    rep = ctx.socket(zmq.REP)  # what `twin serve` listens with
    try:
        address = f"tcp://127.0.0.1:{rep.bind_to_random_port('tcp://127.0.0.1')}"
        start = time.monotonic()
        with pytest.raises(ConfigError, match="did not answer Dask's handshake"):
            connect(address, timeout_s=2)
        assert time.monotonic() - start < 6
    finally:
        rep.close(linger=0)
        ctx.term()


def test_connect_over_tls_takes_the_certificates_from_dasks_configuration(local):
    import dask

    cluster = local["cluster"]
    address = cluster.scheduler_address
    with pytest.raises(ConfigError, match="must name the cluster's CA") as err:
        connect(address, timeout_s=3)
    assert address in str(err.value) and "DASK_DISTRIBUTED__COMM__TLS__CA_FILE" in str(err.value)

    sec = cluster.security  # Dask's configuration takes PEM text as well as file names
    with dask.config.set(
        {
            "distributed.comm.tls.ca-file": sec.tls_ca_file,
            "distributed.comm.tls.client.cert": sec.tls_client_cert,
            "distributed.comm.tls.client.key": sec.tls_client_key,
        }
    ):
        worker = next(iter(local["client"].scheduler_info()["workers"]))
        with pytest.raises(ConfigError, match="is a Dask Worker, not a scheduler"):
            connect(worker, timeout_s=3)
        client = connect(address, timeout_s=5)
        try:
            assert client.submit(lambda: 7, pure=False).result(timeout=30) == 7
        finally:
            client.close()


# --- a cluster secured with the user's own certificates, started by Dask's command line


def _certificates(folder) -> dict[str, str]:
    """A CA and a certificate with its key per role (scheduler, worker, client), signed by it, as
    files: {"ca": path, "scheduler": path, "scheduler-key": path, ...}."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import rsa
    from cryptography.x509.oid import NameOID

    now = datetime.datetime.now(datetime.UTC)
    files = {}

    def write(name: str, data: bytes) -> None:
        path = folder / f"{name}.pem"
        path.write_bytes(data)
        files[name] = str(path)

    def make(cn: str, issuer_name=None, issuer_key=None, ca=False):
        key = rsa.generate_private_key(public_exponent=65537, key_size=2048)
        name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, cn)])
        builder = (
            x509.CertificateBuilder()
            .subject_name(name)
            .issuer_name(issuer_name or name)
            .public_key(key.public_key())
            .serial_number(x509.random_serial_number())
            .not_valid_before(now - datetime.timedelta(minutes=5))
            .not_valid_after(now + datetime.timedelta(days=1))
            .add_extension(x509.BasicConstraints(ca=ca, path_length=None), critical=True)
        )
        if not ca:
            builder = builder.add_extension(
                x509.SubjectAlternativeName(
                    [x509.DNSName("localhost"), x509.IPAddress(ipaddress.ip_address("127.0.0.1"))]
                ),
                critical=False,
            )
        cert = builder.sign(issuer_key or key, hashes.SHA256())
        return key, cert

    ca_key, ca_cert = make("twin-test-ca", ca=True)
    write("ca", ca_cert.public_bytes(serialization.Encoding.PEM))
    for role in ("scheduler", "worker", "client"):
        key, cert = make(f"dask-{role}", ca_cert.subject, ca_key)
        write(role, cert.public_bytes(serialization.Encoding.PEM))
        write(
            f"{role}-key",
            key.private_bytes(
                serialization.Encoding.PEM,
                serialization.PrivateFormat.PKCS8,
                serialization.NoEncryption(),
            ),
        )
    return files


def _stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(5)


CLIENT = """
import sys
from twin.model.errors import ConfigError
from twin.jobs.cluster import connect
try:
    client = connect(sys.argv[1], timeout_s=10)
except ConfigError as err:
    print("ConfigError:", err)
    sys.exit(3)
workers = len(client.scheduler_info()["workers"])
print(client.submit(lambda x: x + 1, 41, pure=False).result(timeout=30), workers)
client.close()
"""


def test_a_cluster_with_the_users_certificates(tmp_path):
    pki = _certificates(tmp_path)
    dask_cli = [sys.executable, "-m", "distributed.cli.dask_scheduler"]
    scheduler_file = tmp_path / "scheduler.json"
    log = (tmp_path / "scheduler.log").open("w")
    scheduler = subprocess.Popen(
        [
            *dask_cli,
            "--protocol",
            "tls",
            "--host",
            "127.0.0.1",
            "--port",
            "0",
            "--dashboard-address",
            "127.0.0.1:0",
            "--tls-ca-file",
            pki["ca"],
            "--tls-cert",
            pki["scheduler"],
            "--tls-key",
            pki["scheduler-key"],
            "--scheduler-file",
            str(scheduler_file),
        ],
        stdout=log,
        stderr=subprocess.STDOUT,
    )
    worker = None
    try:
        deadline = time.monotonic() + 30
        while not scheduler_file.exists() or not scheduler_file.read_text().strip():
            assert scheduler.poll() is None and time.monotonic() < deadline, (
                tmp_path / "scheduler.log"
            ).read_text()
            time.sleep(0.1)
        address = json.loads(scheduler_file.read_text())["address"]
        assert address.startswith("tls://127.0.0.1:")
        worker = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "distributed.cli.dask_worker",
                address,
                "--nworkers",
                "1",
                "--nthreads",
                "1",
                "--host",
                "127.0.0.1",
                "--no-dashboard",
                "--tls-ca-file",
                pki["ca"],
                "--tls-cert",
                pki["worker"],
                "--tls-key",
                pki["worker-key"],
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )

        env = {
            **os.environ,
            "DASK_DISTRIBUTED__COMM__TLS__CA_FILE": pki["ca"],
            "DASK_DISTRIBUTED__COMM__TLS__CLIENT__CERT": pki["client"],
            "DASK_DISTRIBUTED__COMM__TLS__CLIENT__KEY": pki["client-key"],
        }
        while True:  # the worker registers in a second or two
            done = subprocess.run(
                [sys.executable, "-c", CLIENT, address],
                capture_output=True,
                text=True,
                env=env,
                timeout=60,
                check=False,
            )
            assert done.returncode == 0, done.stdout + done.stderr
            if done.stdout.split() == ["42", "1"] or time.monotonic() > deadline:
                break
        assert done.stdout.split() == ["42", "1"], done.stdout + done.stderr

        # without the certificates: connect() says what to configure, and the scheduler refuses them
        # anyway
        bare = {k: v for k, v in env.items() if not k.startswith("DASK_DISTRIBUTED__COMM__TLS__")}
        done = subprocess.run(
            [sys.executable, "-c", CLIENT, address],
            capture_output=True,
            text=True,
            env=bare,
            timeout=60,
            check=False,
        )
        assert done.returncode == 3 and "must name the cluster's CA" in done.stdout, (
            done.stdout + done.stderr
        )
        host, port = address.removeprefix("tls://").rsplit(":", 1)
        # trusts the CA, shows no certificate of its own
        anonymous = ssl.create_default_context(cafile=pki["ca"])
        anonymous.check_hostname = False
        with (
            pytest.raises(ssl.SSLError),
            socket.create_connection((host, int(port)), timeout=5) as raw,
            anonymous.wrap_socket(raw) as tls,
        ):
            tls.sendall(b"\0" * 8)
            # TLS 1.3: the server's refusal of the missing client certificate arrives here
            tls.recv(1)
        assert "TLS" in _refused(address, **Security.temporary().get_connection_args("client"))
        _refused("tcp://" + address.removeprefix("tls://"))
    finally:
        for proc in (worker, scheduler):
            if proc is not None:
                _stop(proc)
        log.close()
