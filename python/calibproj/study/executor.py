"""Where the study's measurements run: a local process pool, or a cluster.

``run_all(function, tasks, workers, cluster)`` maps a top-level function over picklable
tasks and returns the results in the tasks' order, logging one line per result. A
``cluster`` address hands the work to an existing engine instead of a home-made one:
``ray://host:port`` (or ``ray:auto``) to a Ray cluster through
``ray.util.multiprocessing.Pool``, ``tcp://host:port`` to a Dask scheduler through
``dask.distributed.Client``. Their packages are optional (``pip install "ray[client]"``
or ``pip install dask distributed``); a missing one is one clear error. Checked by hand
on a one-node Ray cluster (``ray start --head``, then ``ray:auto``).
"""

from __future__ import annotations

import logging
import urllib.parse
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from typing import Any

logger = logging.getLogger(__name__)


def run_all(function: Callable[[Any], Any], tasks: Sequence[Any], workers: int = 2,
            cluster: str | None = None, what: str = "task") -> list[Any]:
    """``[function(task) for task in tasks]``, run in parallel (module docstring)."""
    if cluster:
        check_cluster_address(cluster)
    if not tasks:
        return []
    if cluster:
        return _on_cluster(function, tasks, cluster, what)
    if workers <= 1:
        return [_logged(function(task), index, len(tasks), what) for index, task in enumerate(tasks)]
    with ProcessPoolExecutor(max_workers=workers) as pool:
        return [_logged(result, index, len(tasks), what) for index, result in enumerate(pool.map(function, tasks))]


def _logged(result: Any, index: int, total: int, what: str) -> Any:
    logger.info("%s %d/%d done", what, index + 1, total)
    return result


def check_cluster_address(address: str) -> None:
    """ValueError naming ``address`` unless it is ray:auto, ray://HOST:PORT or
    tcp://HOST:PORT with a port in 1..65535 (before the engine's own parser sees it)."""
    expected = f"--cluster {address}: expected ray://HOST:PORT, ray:auto or tcp://HOST:PORT (Dask)"
    if address == "ray:auto":
        return
    parts = urllib.parse.urlsplit(address)
    if parts.scheme not in ("ray", "tcp") or not address.startswith(f"{parts.scheme}://"):
        raise ValueError(expected)
    try:
        port = parts.port
    except ValueError:
        port = None
    if not parts.hostname or port is None or not 1 <= port <= 65535 or parts.path or parts.query:
        raise ValueError(expected)


def _on_cluster(function: Callable[[Any], Any], tasks: Sequence[Any], address: str, what: str) -> list[Any]:
    if address.startswith("ray:"):
        try:
            from ray.util.multiprocessing import Pool
        except ImportError:
            raise ValueError(f"--cluster {address}: Ray is not installed (pip install 'ray[client]')") from None
        ray_address = "auto" if address == "ray:auto" else address
        with Pool(ray_address=ray_address) as pool:
            results = pool.map(function, list(tasks))
    elif address.startswith("tcp://"):
        try:
            from dask.distributed import Client
        except ImportError:
            raise ValueError(f"--cluster {address}: Dask's distributed scheduler is not installed "
                             "(pip install dask distributed)") from None
        with Client(address) as client:
            results = client.gather(client.map(function, list(tasks), pure=False))
    else:
        raise ValueError(f"--cluster {address}: expected ray://HOST:PORT, ray:auto or tcp://HOST:PORT (Dask)")
    logger.info("%d %ss done on %s", len(results), what, address)
    return list(results)
