"""Spreading evaluation over a Dask cluster, for users who outgrow one machine."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any


def dask_map(address: str) -> Callable[[Callable, Iterable], list[Any]]:
    """A map function that runs jobs on the Dask scheduler at ``address``.

    Parameters
    ----------
    address : str
        Scheduler address, e.g. ``tcp://10.0.0.5:8786``; a ``distributed.Client`` works too.

    Returns
    -------
    callable
        ``map(function, jobs) -> list of results`` in the jobs' order.
    """
    from distributed import Client

    client = address if isinstance(address, Client) else Client(address)

    def run(function: Callable, jobs: Iterable) -> list[Any]:
        futures = client.map(function, list(jobs), pure=False)
        return client.gather(futures)

    return run
