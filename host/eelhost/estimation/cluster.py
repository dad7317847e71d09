"""Spreading evaluation over a Dask cluster, for users who outgrow one machine.

A :class:`ClusterMap` is the cluster's ``map(function, jobs)``; an evaluator's backend spreads its
work through it (``Evaluator(..., map_function=dask_map(address))``, or a backend object:
``BatchBackend(map_function)`` sends each generation's candidates in blocks, one task each,
``ReferenceBackend(map_function=...)`` one closed-loop run per task). This module imports no
backend: the backends take any map.

What a cluster is trusted with (docs/cli.md, "Security"): Dask sends functions and results between
the client and the workers as pickles, so whoever runs the scheduler or a worker can run code on
the user's machine, and sees the experiments. eelbot therefore connects only to

- ``tls://`` addresses, with Dask's :class:`~distributed.Security`: the certificate authority that
  signed the scheduler's and workers' certificates, and the client's own certificate and key
  (from the options, or else from the Dask configuration, ``distributed.comm.tls.*``); the
  connection is encrypted and both ends are authenticated;
- plain ``tcp://`` on the loopback address (a cluster on this machine, e.g. ``LocalCluster``);
- plain ``tcp://`` elsewhere only with ``insecure=True`` (``--insecure``): for a network where
  every machine that can reach the scheduler is trusted.
"""

from __future__ import annotations

import ipaddress
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

from eelhost.errors import UserError

CONNECT_TIMEOUT_S = 5.0  # a scheduler that has not answered by then is not there
BLOCKS_PER_WORKER = 2  # blocks of runs per worker and generation: some balance, little overhead


class ClusterError(UserError, ConnectionError):
    """A cluster scheduler that cannot be reached or is not trusted; the message names its address."""


@dataclass(frozen=True)
class TLSFiles:
    """The client's side of a ``tls://`` connection (None: from the Dask configuration).

    Attributes
    ----------
    ca_file : str or None
        The certificate authority that signed the scheduler's and workers' certificates.
    cert, key : str or None
        The client's certificate and private key (PEM).
    """

    ca_file: str | None = None
    cert: str | None = None
    key: str | None = None


def _is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False  # a name: it may resolve anywhere


def security_for(address: str, tls: TLSFiles | None = None, insecure: bool = False) -> Any:
    """The :class:`distributed.Security` to reach ``address`` with, or refuse the address.

    Parameters
    ----------
    address : str
        ``tls://host:port``, ``tcp://host:port`` or ``host:port`` (TCP).
    tls : TLSFiles, optional
        Certificates for ``tls://`` (default: the Dask configuration's).
    insecure : bool
        Allow plain TCP to another machine.

    Returns
    -------
    distributed.Security or None
        None for plain TCP.

    Raises
    ------
    ClusterError
        An address that is not a scheduler's, plain TCP to another machine without ``insecure``,
        another protocol, or ``tls://`` without a certificate authority and client certificate.
    """
    from distributed import Security
    from distributed.comm import parse_address
    from distributed.comm.addressing import parse_host_port

    try:
        scheme, location = parse_address(address)
        host, _ = parse_host_port(location)
    except (ValueError, TypeError) as err:
        raise ClusterError(
            f"--scheduler {address}: not a scheduler address ({err}; e.g. tls://host:8786)"
        ) from None
    if scheme == "tcp":
        if _is_loopback(host) or insecure:
            return None
        raise ClusterError(
            f"--scheduler {address}: plain TCP to another machine is refused: whoever can reach "
            "the scheduler can run code on this machine through it; use tls:// with "
            "certificates (docs/cli.md, \"Security\"), or --insecure on a network you trust"
        )
    if scheme != "tls":
        raise ClusterError(f"--scheduler {address}: protocol {scheme}:// is not supported "
                           "(tls://, or tcp:// on this machine)")
    tls = tls or TLSFiles()
    given = {k: v for k, v in (("tls_ca_file", tls.ca_file), ("tls_client_cert", tls.cert),
                               ("tls_client_key", tls.key)) if v}
    security = Security(require_encryption=True, **given)  # the rest from the Dask config
    # (Security sets its attributes from keywords and the config: getattr for the type checker)
    if not getattr(security, "tls_ca_file", None) or not getattr(security, "tls_client_cert", None):
        raise ClusterError(
            f"--scheduler {address}: tls:// needs the cluster's certificate authority and a "
            "client certificate: --tls-ca-file and --tls-cert (and --tls-key), or "
            "distributed.comm.tls.ca-file and distributed.comm.tls.client.cert in the Dask "
            "configuration"
        )
    return security


class ClusterMap:
    """``map(function, jobs)`` on a Dask client, and how many workers it has.

    Parameters
    ----------
    client : distributed.Client
    """

    def __init__(self, client: Any) -> None:
        self.client = client
        self._shared: dict[int, tuple[Any, Any]] = {}

    @property
    def workers(self) -> int:
        """Workers connected now (at least 1)."""
        return max(1, len(self.client.scheduler_info().get("workers", {})))

    @property
    def blocks(self) -> int:
        """How many blocks to cut a generation's runs into."""
        return BLOCKS_PER_WORKER * self.workers

    def share(self, value: Any) -> Any:
        """``value`` sent once to every worker; jobs may hold the returned future instead."""
        key = id(value)
        if key not in self._shared:  # kept with the value, so that its id is not reused
            self._shared[key] = (value, self.client.scatter(value, broadcast=True, hash=False))
        return self._shared[key][1]

    def close(self) -> None:
        """Disconnect from the scheduler (the cluster itself goes on)."""
        self.client.close()

    def __call__(self, function: Callable, jobs: Iterable) -> list[Any]:
        """Run ``function`` on every job on the cluster; results in the jobs' order.

        The jobs are dealt round the workers connected now (another may take one when its own is
        busy or gone). Left to itself the scheduler put a generation's blocks, all depending on
        the same shared experiments, on one worker: on an idle machine the second worker of the
        cluster benchmark got almost no work (docs/benchmarks.md, section 5).
        """
        workers = sorted(self.client.scheduler_info().get("workers", {}))
        if not workers:
            # none connected as seen from here (one may be registering, or the scheduler's
            # report lags under load): the scheduler places the jobs itself; Dask refuses
            # allow_other_workers without workers (ValueError, seen in a loaded fresh clone)
            return self.client.gather([self.client.submit(function, job, pure=False)
                                       for job in jobs])
        futures = [
            self.client.submit(function, job, pure=False, allow_other_workers=True,
                               workers=[workers[i % len(workers)]])
            for i, job in enumerate(jobs)
        ]
        return self.client.gather(futures)


def dask_map(
    address: Any, timeout_s: float | None = None, tls: TLSFiles | None = None,
    insecure: bool = False,
) -> ClusterMap:
    """A map function that runs jobs on the Dask scheduler at ``address``.

    Parameters
    ----------
    address : str or distributed.Client
        Scheduler address (``tls://host:8786``; see :func:`security_for`), or a client.
    timeout_s : float, optional
        How long to try to reach the scheduler before :class:`ClusterError` (default
        :data:`CONNECT_TIMEOUT_S`).
    tls : TLSFiles, optional
        Certificates for ``tls://``.
    insecure : bool
        Allow plain TCP to another machine.

    Returns
    -------
    ClusterMap
        ``map(function, jobs) -> list of results`` in the jobs' order.
    """
    from distributed import Client

    if isinstance(address, Client):
        return ClusterMap(address)
    timeout_s = CONNECT_TIMEOUT_S if timeout_s is None else timeout_s
    security = security_for(address, tls, insecure)
    try:
        client = Client(address, timeout=timeout_s, security=security)
    except ValueError as err:
        raise ClusterError(
            f"--scheduler {address}: not a scheduler address ({err}; e.g. tls://host:8786)"
        ) from None
    except (OSError, TimeoutError) as err:
        raise ClusterError(
            f"--scheduler {address}: no Dask scheduler answered within {timeout_s:g} s "
            f"({type(err).__name__}: {err})"
        ) from None
    return ClusterMap(client)
