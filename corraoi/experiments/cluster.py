"""Chunks of a sweep on a Dask cluster (``dask.distributed``: the optional extra ``cluster``).

``--scheduler tcp://HOST:PORT`` connects to a running scheduler; ``--scheduler local:N``
starts a LocalCluster of N single-threaded worker processes on 127.0.0.1 (stopped when the
sweep ends). Chunks go out as plain data (:func:`corraoi.experiments.chunks.chunk_task`: the
instance, the policy and a file plug-in's source travel with them) and come back as arrays;
only this process writes files. A chunk whose worker dies is retried on another (Dask's
``retries``); a chunk that fails for its own reasons stops the sweep with one line.
Imported only when a scheduler is asked for: a plain sweep never imports Dask.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

from corraoi._version import __version__
from corraoi.errors import ClusterError, ConfigError, CorraoiError, MissingExtraError

#: Tries of a chunk whose worker died before it is given up.
RETRIES = 3
#: Seconds to wait for a scheduler to answer ($CORRAOI_CONNECT_TIMEOUT overrides).
CONNECT_TIMEOUT = float(os.environ.get("CORRAOI_CONNECT_TIMEOUT", "10"))


def _dask() -> Any:
    try:
        import dask.distributed as dd
    except ImportError:
        raise MissingExtraError(
            'running on a Dask cluster needs the cluster extra: pip install "corraoi[cluster]"'
        ) from None
    return dd


def _worker_version() -> str:
    from corraoi._version import __version__ as installed  # the worker's own corraoi

    return installed


def _worker_setup(threads: int) -> str:
    """Run on every worker: limit the engine's threads so workers do not oversubscribe cores."""
    from corraoi.engine.threads import set_workers

    set_workers(threads)
    return _worker_version()


@contextmanager
def connect(scheduler: str, *, threads_per_worker: int = 1) -> Iterator[Any]:
    """A ``Client`` for ``tcp://HOST:PORT`` or ``local:N`` (a LocalCluster on 127.0.0.1)."""
    dd = _dask()
    cluster = None
    text = scheduler.strip()
    try:
        if text.startswith("local:"):
            try:
                n = int(text[len("local:") :])
            except ValueError:
                n = 0
            if n < 1 or n > 1024:
                raise ConfigError(
                    f"--scheduler {scheduler}: expected local:N with N workers, 1..1024"
                )
            cluster = dd.LocalCluster(
                n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                dashboard_address=None, silence_logs=50,
            )  # fmt: skip
            client = dd.Client(cluster)
        elif "://" in text:
            try:
                client = dd.Client(text, timeout=CONNECT_TIMEOUT)
            except (OSError, TimeoutError) as exc:
                raise ClusterError(
                    f"--scheduler {scheduler}: cannot reach the scheduler "
                    f"({type(exc).__name__}: {' '.join(str(exc).split())[:200]})"
                ) from None
        else:
            raise ConfigError(
                f"--scheduler {scheduler}: expected tcp://HOST:PORT (a running dask scheduler) "
                "or local:N (N local workers)"
            )
        try:
            if cluster is None:  # workers may still be connecting to a fresh scheduler
                try:
                    client.wait_for_workers(1, timeout=CONNECT_TIMEOUT)
                except (OSError, TimeoutError):
                    raise ClusterError(
                        f"--scheduler {scheduler}: no worker joined within "
                        f"{CONNECT_TIMEOUT:g} s (start some with `dask worker {text}`)"
                    ) from None
            versions = client.run(_worker_setup, threads_per_worker)
            bad = {w: v for w, v in versions.items() if v != __version__}
            if bad:
                worker, version = next(iter(bad.items()))
                raise ClusterError(
                    f"worker {worker} runs corraoi {version}, this client {__version__}: "
                    "install the same version on every worker"
                )
            if not versions:
                raise ClusterError(f"--scheduler {scheduler}: the cluster has no worker")
            yield client
        finally:
            client.close()
    finally:
        if cluster is not None:
            cluster.close()


def run_on_cluster(
    client: Any,
    tasks: list[tuple[Any, dict[str, Any]]],
    *,
    on_done: Callable[[Any], None],
) -> None:
    """Submit every chunk, and hand each result to ``on_done`` as it arrives (any order)."""
    dd = _dask()
    import uuid

    from .chunks import run_chunk

    token = uuid.uuid4().hex[:8]  # a sweep's own keys: a client may run the same grid twice
    futures = [
        client.submit(run_chunk, task, key=f"corraoi-{chunk.name}-{token}", retries=RETRIES,
                      pure=False)  # fmt: skip
        for chunk, task in tasks
    ]
    try:
        for future in dd.as_completed(futures):
            try:
                result = future.result()
            except CorraoiError:
                raise
            except Exception as exc:
                name = type(exc).__name__
                if name == "KilledWorker":
                    raise ClusterError(
                        f"a chunk killed {RETRIES + 1} workers in a row ({future.key}): "
                        "finished chunks are saved; --resume continues"
                    ) from None
                raise ClusterError(
                    f"chunk {future.key} failed on the cluster: {name}: "
                    f"{' '.join(str(exc).split())[:300]}"
                ) from None
            on_done(result)
    finally:
        for f in futures:
            if not f.done():
                f.cancel()
