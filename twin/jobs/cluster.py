"""Starting or reaching a Dask cluster safely: `start_local` and `connect`.

`start_local(jobs)` starts a LocalCluster-like SpecCluster of `jobs` single-threaded worker
processes (each with its nanny) on 127.0.0.1 whose scheduler, nannies and workers speak TLS only
(tls://, require_encryption) with a throwaway certificate made for the run (`Security.temporary()`,
kept in memory): only this process's client and the workers it started can talk to the scheduler,
not any other local process (without it, anyone on the machine could connect a Client and run code
in the workers as the sweep's user). Dask's scheduler serves HTTP (/metrics, /health, /info, /json)
on 127.0.0.1:8787 even with dashboard_address=None (Scheduler.__init__ calls start_http_server
unconditionally, and Node.start_http_server binds `dashboard_address or 8787`), and every worker on
a random port; here neither has an HTTP server at all, unless `dashboard=True` asks for the
scheduler's dashboard, then on 127.0.0.1 on a free port (its URL is returned).

`connect(address)` reaches a running cluster (`--scheduler`) in bounded time: Client(timeout=10)
bounds only the TCP connect, not the handshake read that follows it (distributed/comm/core.py,
connect(): `await comm.write(local_info); handshake = await comm.read()`), so a port that accepts
and never answers (a `twin serve` ZeroMQ socket) kept it waiting for ever. connect() first speaks to
the address itself under one deadline (handshake and an `identity` request: a scheduler answers with
its workers) and only then starts the Client. For tls:// it takes the certificates from Dask's
configuration (see `connect`).

The secured external cluster, from Dask's own command line (verified with distributed 2026.8.0). One
CA, and a certificate with its key per role signed by it (Dask checks the chain, not host names):

    openssl req -x509 -newkey rsa:2048 -nodes -days 365 -subj /CN=twin-dask-ca \\
        -keyout ca-key.pem -out ca.pem
    for role in scheduler worker client; do
      openssl req -newkey rsa:2048 -nodes -subj /CN=dask-$role -keyout $role-key.pem -out $role.csr
      openssl x509 -req -in $role.csr -CA ca.pem -CAkey ca-key.pem -CAcreateserial -days 365 \\
        -out $role.pem -extfile <(printf \\
        "subjectAltName=DNS:localhost,IP:127.0.0.1\\nextendedKeyUsage=serverAuth,clientAuth")
    done
    DASK_DISTRIBUTED__SCHEDULER__HTTP__ROUTES='[]' dask scheduler --protocol tls --host HOST \\
        --port 8786 --dashboard-address 127.0.0.1:0 \\
        --tls-ca-file ca.pem --tls-cert scheduler.pem --tls-key scheduler-key.pem
    DASK_DISTRIBUTED__WORKER__HTTP__ROUTES='[]' dask worker tls://HOST:8786 --nworkers 1 \\
        --nthreads 1 --preload twin.sweep.worker \\
        --tls-ca-file ca.pem --tls-cert worker.pem --tls-key worker-key.pem
    DASK_DISTRIBUTED__COMM__TLS__CA_FILE=ca.pem \\
    DASK_DISTRIBUTED__COMM__TLS__CLIENT__CERT=client.pem \\
    DASK_DISTRIBUTED__COMM__TLS__CLIENT__KEY=client-key.pem \\
        twin sweep ... --executor dask --scheduler tls://HOST:8786

`dask scheduler` serves HTTP whatever its options (--no-dashboard drops only the Bokeh pages;
/metrics, /health, /info, /json stay): the empty routes make every page a 404 and
--dashboard-address keeps the port on loopback. A client without the CA's client certificate is
refused in the TLS handshake.

This module imports Dask only when called (`import twin.jobs.cluster` stays cheap); the classes
QuietScheduler and QuietWorker are made on first use (module __getattr__), also when a spawned
worker process unpickles its class by name.
"""

from __future__ import annotations

import asyncio
import logging
import threading
from collections.abc import Mapping, Sequence

from twin.model.errors import ConfigError, exception_text

HOST = "127.0.0.1"
CONNECT_TIMEOUT_S = 10.0
# the handshake's bound past the connect timeout (Dask's connect bounds only the connect)
PROBE_GRACE_S = 2.0

# A local cluster's scheduler, nannies and workers take this configuration (set while the cluster
# starts, and given to the nannies for the worker processes they spawn, also those they restart).
# Their event loops' periodic work runs beside the simulation (in a worker, a thread that takes the
# GIL from it; the scheduler on the same cores): idle, with Dask's defaults, the scheduler's process
# took 4.4 % of a core and each worker 1.7-1.9 %; with the tick and memory-check intervals below 1.1
# % and 0.3-0.4 %, and the scheduler's process used 0.06-0.09 s of CPU per 150-scenario sweep
# instead of 0.14-0.20 s (measured).
WORKER_CONFIG = {
    # its 10 ms stack sampling takes the GIL from the simulation
    "distributed.worker.profile.enabled": False,
    "distributed.admin.system-monitor.interval": "2s",
    # an event-loop health check (for warnings), default 20 ms
    "distributed.admin.tick.interval": "500ms",
    # spill/pause/terminate checks, default 100 ms
    "distributed.worker.memory.monitor-interval": "1s",
    # Dask sets MALLOC_TRIM_THRESHOLD_=65536 in its workers, which makes glibc return memory at
    # every free and turns off its adaptive threshold; the simulation allocates all the time (and
    # the guarded children that run scenarios keep freed memory: worker.keep_freed_memory). Threads
    # stay at 1.
    "distributed.nanny.pre-spawn-environ": {
        "OMP_NUM_THREADS": 1,
        "MKL_NUM_THREADS": 1,
        "OPENBLAS_NUM_THREADS": 1,
    },
}

TLS_ENV = (
    "DASK_DISTRIBUTED__COMM__TLS__CA_FILE=ca.pem "
    "DASK_DISTRIBUTED__COMM__TLS__CLIENT__CERT=client.pem "
    "DASK_DISTRIBUTED__COMM__TLS__CLIENT__KEY=client-key.pem"
)
_QUIET = ("QuietScheduler", "QuietWorker")


def _need_dask():
    try:
        import dask
        import distributed
    except ImportError as err:
        raise ConfigError(
            "--executor dask needs Dask's distributed scheduler; "
            "install it with pip install 'twin[dask]'"
        ) from err
    return dask, distributed


def _no_http_server(self, routes, dashboard_address, default_port=0, ssl_options=None) -> None:
    """Node.start_http_server, replaced: no HTTP server, no port (no /metrics, /health, /info)."""


def _define_quiet_classes() -> tuple[type, type]:
    """(QuietScheduler, QuietWorker): Dask's Scheduler and Worker without an HTTP server, made
    once."""
    from distributed import Scheduler, Worker

    for name, base in zip(_QUIET, (Scheduler, Worker)):
        if name not in globals():
            globals()[name] = type(
                name,
                (base,),
                {
                    "__module__": __name__,
                    "start_http_server": _no_http_server,
                    "__doc__": f"Dask's {base.__name__} without its HTTP server "
                    f"(twin.jobs.cluster).",
                },
            )
    return globals()[_QUIET[0]], globals()[_QUIET[1]]


def __getattr__(name: str):
    if name in _QUIET:
        return dict(zip(_QUIET, _define_quiet_classes()))[name]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _line(err: BaseException) -> str:
    text = exception_text(err).strip()
    first = text.splitlines()[0] if text else ""
    return f"{type(err).__name__}: {first}" if first else type(err).__name__


def start_local(
    jobs: int,
    *,
    dashboard: bool = False,
    preload: Sequence[str] = (),
    config: Mapping[str, object] = WORKER_CONFIG,
):
    """A TLS-secured cluster of `jobs` single-threaded worker processes on 127.0.0.1 and this
    process's client of it: (cluster, client, dashboard URL or None). The certificate is made for
    this cluster and held in memory (cluster.security): a client needs it to connect. No HTTP server
    runs unless `dashboard` (then the scheduler's, on 127.0.0.1 on a free port). `preload` is
    imported in each worker as it starts; `config` is Dask configuration set while the cluster
    starts. Close the client, then the cluster."""
    dask, _ = _need_dask()
    from distributed import Client, Nanny, Scheduler, SpecCluster
    from distributed.security import Security

    if jobs < 1:
        raise ConfigError(f"a local Dask cluster needs at least 1 worker; got {jobs}")
    try:
        # a self-signed CA/certificate/key for every role, in memory only
        security = Security.temporary()
    except ImportError as err:
        raise ConfigError(
            "a local Dask cluster is secured with a throwaway TLS certificate, which needs "
            "the cryptography package; install it with pip install 'twin[dask]'"
        ) from err
    quiet_scheduler, quiet_worker = _define_quiet_classes()
    settings = dict(config)
    # Scheduler.__init__ appends to the routes list it reads from the configuration when bokeh is
    # missing: a copy of it keeps the process's configuration unchanged
    settings["distributed.scheduler.http.routes"] = list(
        dask.config.get("distributed.scheduler.http.routes")
    )
    scheduler_options, worker_options = _options(jobs, security, dashboard, preload, config)
    # a spawned worker process unpickles it by name: module __getattr__
    worker_options["worker_class"] = quiet_worker
    worker = {"cls": Nanny, "options": worker_options}
    cluster = client = None
    try:
        with dask.config.set(settings):
            cluster = SpecCluster(
                scheduler={
                    "cls": Scheduler if dashboard else quiet_scheduler,
                    "options": scheduler_options,
                },
                workers={i: worker for i in range(jobs)},
                worker=worker,
                security=security,
                silence_logs=logging.ERROR,
                name="twin",
            )
            client = Client(cluster, security=security, set_as_default=False)
    except (OSError, TimeoutError, RuntimeError, ValueError) as err:
        # RuntimeError: a worker could not start
        for part in (client, cluster):
            if part is not None:
                part.close()
        raise ConfigError(
            f"cannot start a local Dask cluster of {jobs} workers on {HOST}: {_line(err)} "
            "(a script that starts one needs the if __name__ == '__main__': guard)"
        ) from err
    url = (cluster.dashboard_link or None) if dashboard else None
    return cluster, client, url


def _options(
    jobs: int, security, dashboard: bool, preload: Sequence[str], config: Mapping
) -> tuple[dict, dict]:
    """The scheduler's and each worker's options for start_local (the worker class is added by the
    caller): TLS on 127.0.0.1, one thread a worker, no HTTP server unless dashboard."""
    from distributed.worker_memory import parse_memory_limit

    scheduler_options = {
        "host": HOST,
        "port": 0,
        "protocol": "tls://",
        "security": security,
        "services": {},
        "dashboard": dashboard,
        "dashboard_address": f"{HOST}:0" if dashboard else None,
    }
    worker_options = {
        "host": HOST,
        "protocol": "tls://",
        "security": security,
        "nthreads": 1,
        # as LocalCluster
        "memory_limit": parse_memory_limit("auto", 1, jobs, logger=logging.getLogger(__name__)),
        "dashboard": False,
        "dashboard_address": None,
        "silence_logs": logging.ERROR,
        "preload": list(preload),
        # a nanny hands its worker processes a shallow copy of the configuration taken as it starts,
        # whose nested dicts dask.config.set's context restores in place as it ends: without
        # `config` here, a worker that the nanny restarts later would get Dask's defaults
        "config": dict(config),
    }
    return scheduler_options, worker_options


class _Deadline(Exception):
    """The probe's deadline passed: a connection was made but no Dask handshake came back."""


def _run_with_deadline(make_coro, timeout_s: float):
    """make_coro()'s result, run in a fresh event loop in its own thread and cancelled at timeout_s
    (_Deadline then); never waits much past the deadline."""
    box: dict[str, object] = {}

    async def bounded():
        try:
            async with asyncio.timeout(timeout_s) as scope:
                return await make_coro()
        except TimeoutError as err:
            if scope.expired():  # this deadline's, not a TimeoutError from inside
                raise _Deadline() from err
            raise

    def run() -> None:
        try:
            box["result"] = asyncio.run(bounded())
        except BaseException as err:  # noqa: BLE001 - handed to the caller, which raises it
            box["error"] = err

    thread = threading.Thread(target=run, name="twin-dask-connect", daemon=True)
    thread.start()
    thread.join(timeout_s + PROBE_GRACE_S)
    if thread.is_alive():
        raise _Deadline()
    if "error" in box:
        raise box["error"]
    return box["result"]


def _security_for(address: str):
    """Security from Dask's configuration (the Client's default); for tls:// it must name the CA and
    this client's certificate."""
    from distributed.security import Security

    try:
        security = Security()
    except (ValueError, TypeError) as err:
        raise ConfigError(f"Dask's TLS configuration is invalid: {_line(err)}") from err
    if address.startswith("tls://"):
        if not security.tls_ca_file or not security.tls_client_cert:
            raise ConfigError(
                f"--scheduler {address!r} speaks TLS: Dask's configuration must name the "
                f"cluster's CA and this "
                f"client's certificate (distributed.comm.tls.ca-file, "
                f"distributed.comm.tls.client.cert and "
                f".key), e.g. {TLS_ENV}"
            )
        try:
            # reads the files now: a missing or bad one is named here
            security.get_connection_args("client")
        except (OSError, ValueError) as err:
            raise ConfigError(
                f"cannot load the TLS certificates for --scheduler {address!r} "
                f"(distributed.comm.tls.ca-file, .client.cert, .client.key): {_line(err)}"
            ) from err
    return security


def _probe(address: str, security, timeout_s: float) -> dict:
    """The identity a Dask server at `address` gives after the handshake. Dask's connect retries a
    refused or failed connection for timeout_s, then raises OSError; the handshake and the reply
    that follow have no bound of their own, so the whole probe stops PROBE_GRACE_S later
    (_Deadline)."""
    from distributed.comm import connect as comm_connect
    from distributed.core import send_recv

    async def identity() -> dict:
        comm = await comm_connect(
            address, timeout=timeout_s, **security.get_connection_args("client")
        )
        try:
            return await send_recv(comm, op="identity")
        finally:
            comm.abort()

    return _run_with_deadline(identity, timeout_s + PROBE_GRACE_S)


def connect(address: str, timeout_s: float = CONNECT_TIMEOUT_S):
    """A Client of the Dask scheduler at `address` (tcp://HOST:PORT, tls://HOST:PORT), reached
    within about timeout_s or ConfigError (one line: the address, what was expected, why). For
    tls:// the certificates come from Dask's configuration: distributed.comm.tls.ca-file,
    .client.cert and .client.key (in ~/.config/dask/*.yaml or DASK_DISTRIBUTED__COMM__TLS__CA_FILE,
    DASK_DISTRIBUTED__COMM__TLS__CLIENT__CERT, DASK_DISTRIBUTED__COMM__TLS__CLIENT__KEY)."""
    _need_dask()
    from distributed import Client

    if not address.startswith(("tcp://", "tls://")):
        raise ConfigError(
            f"--scheduler {address!r} is invalid; expected tcp://HOST:PORT or tls://HOST:PORT"
        )
    security = _security_for(address)
    within = f"{timeout_s:g} s"
    hint = "; a cluster secured with TLS needs tls://" if address.startswith("tcp://") else ""
    try:
        info = _probe(address, security, timeout_s)
    except _Deadline as err:
        raise ConfigError(
            f"cannot reach the Dask scheduler {address!r} within {within}: it accepted "
            f"the connection "
            "but did not answer Dask's handshake (expected a Dask scheduler's address, not another "
            "server's)"
        ) from err
    except OSError as err:
        # refused or unreachable (retried for timeout_s), TLS refused, closed mid-handshake
        # Dask's "Timed out trying to connect" names the last attempt's error only here
        cause = err.__cause__
        why = _line(err) + (
            f" ({_line(cause)})" if cause is not None and exception_text(cause) else ""
        )
        raise ConfigError(
            f"cannot reach the Dask scheduler {address!r} within {within}: {why} "
            f"(expected a Dask scheduler's address{hint})"
        ) from err
    except Exception as err:
        # bytes that are not Dask's protocol (a length of exabytes: MemoryError...)
        raise ConfigError(
            f"cannot reach the Dask scheduler {address!r} within {within}: it answered, but not in "
            f"Dask's protocol ({_line(err)}); expected a Dask scheduler's address"
        ) from err
    if not isinstance(info, dict) or "workers" not in info:
        kind = str(info.get("type")) if isinstance(info, dict) else ""
        # QuietWorker: a Worker
        kind = next((k for k in ("Worker", "Nanny") if k in kind), "server")
        raise ConfigError(
            f"--scheduler {address!r} is a Dask {kind}, not a scheduler; "
            "expected the scheduler's address (dask scheduler prints it)"
        )
    # the Client's own timeout is also its default for later calls (gather, close...): the full one
    try:
        return Client(address, timeout=timeout_s, security=security, set_as_default=False)
    except Exception as err:  # OSError, TimeoutError, a version or TLS refusal
        raise ConfigError(
            f"cannot reach the Dask scheduler {address!r} within {within}: {_line(err)} "
            f"(expected a Dask scheduler's address{hint})"
        ) from err
