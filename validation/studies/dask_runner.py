"""Independent runs of a study on Dask: the scheduler, the workers' cache, the results.

Shared by the sweep (:mod:`gearsym.validation.studies.sweep`) and the fleet evaluation
(:mod:`gearsym.validation.studies.estimation.fleet_eval`): a ``dask.distributed`` ``Client`` of
a new ``LocalCluster`` (``"local"``) or of a running scheduler (``tcp://HOST:PORT``), refused in
one line when it cannot be reached or has no workers; one small object every task carries; on
each worker a cache of what is expensive to build (a simulator, a filter's model), keyed by the
content it is built from; the results gathered as they complete, a worker that died or a
scheduler lost on the way being a one-line error too.

Every error here is a :class:`~gearsym.symbolic.errors.GearsymError` naming ``where``, the
command and option that chose the scheduler (``("sweep", "scheduler")``,
``("estimate", "--scheduler")``).
"""

from __future__ import annotations

import hashlib
import pickle
from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import Any

from gearsym.symbolic.errors import GearsymError

__all__ = [
    "WORKER_WAIT",
    "check_scheduler",
    "completed",
    "connect",
    "content_key",
    "submit_each",
    "worker_cached",
]

#: How long a remote scheduler may take to show one worker (s).
WORKER_WAIT = 10.0

#: What each worker process built, by :func:`content_key` of what it was built from.
_WORKER_CACHE: dict[str, Any] = {}


def check_scheduler(scheduler: str, where: tuple[str, str] = ("sweep", "scheduler")) -> None:
    """``local`` or ``tcp://HOST:PORT``, refused in one line before any work otherwise."""
    if scheduler == "local":
        return
    if scheduler.startswith("tls://"):
        raise GearsymError(
            *where,
            f"{scheduler}: TLS needs certificates gearsym does not configure; reach the "
            "scheduler by tcp://HOST:PORT (through an SSH tunnel across networks)",
        )
    if not scheduler.startswith("tcp://"):
        raise GearsymError(*where, f"expected local or tcp://HOST:PORT, got {scheduler!r}")


def connect(
    scheduler: str,
    workers: int,
    processes: bool = True,
    where: tuple[str, str] = ("sweep", "scheduler"),
    wait: float | None = None,
) -> tuple[Any, Any]:
    """(client, cluster or None): a new LocalCluster of ``workers`` single-threaded workers
    for ``"local"``, else the scheduler at ``scheduler`` (``tcp://HOST:PORT``); an unreachable
    one, or one that shows no worker within ``wait`` s (default :data:`WORKER_WAIT`), is a
    one-line error."""
    from dask.distributed import Client, LocalCluster

    if scheduler == "local" and workers < 1:
        # a LocalCluster of no worker would wait for one forever
        raise GearsymError("--workers", "", f"must be at least 1, got {workers}")

    if scheduler == "local":
        cluster = LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            processes=processes,
            dashboard_address=":0",
        )
        return Client(cluster), cluster
    check_scheduler(scheduler, where)
    wait = WORKER_WAIT if wait is None else wait
    try:
        client = Client(scheduler, timeout="5s")
    except (OSError, TimeoutError, ValueError, TypeError, RuntimeError) as err:
        reason = str(err).splitlines()[0] if str(err) else type(err).__name__
        raise GearsymError(*where, f"cannot reach {scheduler}: {reason}") from None
    try:
        client.wait_for_workers(1, timeout=wait)
    except (TimeoutError, OSError) as err:
        client.close()
        raise GearsymError(
            *where,
            f"{scheduler} has no workers (none joined within {wait:g} s): start "
            "`dask worker` processes against it",
        ) from err
    return client, None


def content_key(*objects: Any) -> str:
    """A key of what ``objects`` hold (SHA-256 of their pickle): equal content, equal key,
    in any process."""
    return hashlib.sha256(pickle.dumps(objects)).hexdigest()


def worker_cached(key: str, build: Callable[[], Any]) -> Any:
    """``build()`` once per process and ``key`` (:func:`content_key` of what it is built
    from); later calls with the same key return the same object."""
    value = _WORKER_CACHE.get(key)
    if value is None:
        value = build()
        _WORKER_CACHE[key] = value
    return value


def submit_each(
    client: Any,
    function: Callable[..., Any],
    shared: Any,
    items: Sequence[Any],
    *args: Any,
) -> dict[Any, int]:
    """``function(shared, item, *args)`` for every item as one task each. Future → the item's
    index. ``shared`` travels with every task, not scattered once: it is small (a description,
    a scenario; what is expensive is built on the workers, :func:`worker_cached`), and a task
    the scheduler retries after its worker died still has it (scattered data dies with the
    last worker holding it, and the tasks that need it are cancelled)."""
    return {
        client.submit(function, shared, item, *args, pure=False): i for i, item in enumerate(items)
    }


def completed(
    futures: Mapping[Any, int], where: tuple[str, str] = ("sweep", "scheduler")
) -> Iterator[tuple[int, Any]]:
    """(index, result) of every future as it completes. A worker that died running a task
    (the scheduler gave up on it: ``KilledWorker``) or a scheduler lost on the way is a
    one-line error; an exception the task itself raised is raised here as it would be in
    this process."""
    from concurrent.futures import CancelledError

    from dask.distributed import as_completed
    from distributed import KilledWorker
    from distributed.comm.core import CommClosedError

    try:
        for future in as_completed(futures):
            yield futures[future], future.result()
    except KilledWorker as err:
        raise GearsymError(
            *where,
            "a Dask worker died while running a task and the scheduler gave up on it "
            f"({_first_sentence(err)}): see the worker's log (memory, a crash in native code)",
        ) from None
    except (CommClosedError, CancelledError) as err:
        raise GearsymError(
            *where,
            f"the run was cancelled on the Dask scheduler ({_first_sentence(err)}): a lost "
            "connection, or the scheduler gave up on a task; see its log",
        ) from None


def run_each(
    function: Callable[[Any, Any], Any],
    shared: Any,
    items: Sequence[Any],
    scheduler: str | None,
    workers: int,
    where: tuple[str, str],
    progress: Callable[[int, int], None] | None = None,
) -> list[Any]:
    """``function(shared, item)`` for every item, in item order: in this process
    (``scheduler`` None) or one task each on Dask (``"local"``: a LocalCluster of ``workers``;
    ``tcp://HOST:PORT``), ``progress(done, total)`` after each."""
    results: list[Any] = [None] * len(items)
    if scheduler is None:
        for i, item in enumerate(items):
            results[i] = function(shared, item)
            if progress is not None:
                progress(i + 1, len(items))
        return results
    client, cluster = connect(scheduler, workers, where=where)
    try:
        futures = submit_each(client, function, shared, list(items))
        for done, (i, outcome) in enumerate(completed(futures, where), 1):
            results[i] = outcome
            if progress is not None:
                progress(done, len(items))
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    return results


def _first_sentence(err: BaseException) -> str:
    text = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
    sentence = text.split(". ")[0].rstrip(".")
    return sentence if len(sentence) <= 160 else sentence[:157] + "..."
