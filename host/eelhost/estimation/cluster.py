"""Spreading evaluation over a Dask cluster, for users who outgrow one machine."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

from eelhost.errors import UserError

CONNECT_TIMEOUT_S = 5.0  # a scheduler that has not answered by then is not there


class ClusterError(UserError, ConnectionError):
    """A cluster scheduler that cannot be reached; the message names its address."""


def dask_map(
    address: str, timeout_s: float | None = None
) -> Callable[[Callable, Iterable], list[Any]]:
    """A map function that runs jobs on the Dask scheduler at ``address``.

    Parameters
    ----------
    address : str
        Scheduler address, e.g. ``tcp://10.0.0.5:8786``; a ``distributed.Client`` works too.
    timeout_s : float, optional
        How long to try to reach the scheduler before :class:`ClusterError` (default
        :data:`CONNECT_TIMEOUT_S`).

    Returns
    -------
    callable
        ``map(function, jobs) -> list of results`` in the jobs' order.
    """
    from distributed import Client

    timeout_s = CONNECT_TIMEOUT_S if timeout_s is None else timeout_s
    client: Client
    if isinstance(address, Client):
        client = address
    else:
        try:
            client = Client(address, timeout=timeout_s)
        except ValueError as err:
            raise ClusterError(
                f"--scheduler {address}: not a scheduler address ({err}; e.g. tcp://host:8786)"
            ) from None
        except (OSError, TimeoutError) as err:
            raise ClusterError(
                f"--scheduler {address}: no Dask scheduler answered within {timeout_s:g} s "
                f"({type(err).__name__}: {err})"
            ) from None

    def run(function: Callable, jobs: Iterable) -> list[Any]:
        futures = client.map(function, list(jobs), pure=False)
        return client.gather(futures)

    return run
