"""Where a batch job's tasks run: this process, a pool of worker processes, or a Dask cluster.

:func:`run_tasks` picks the executor. The local pool (:func:`_run_pool`) replaces a worker that
dies or exceeds ``--timeout`` and retries only its task (``--retries``); on Dask (:func:`_run_dask`)
the scheduler reschedules a lost worker's task itself, and every attempt is read back from the
markers the attempts left in the job's folder (:func:`_attempts_from_markers`).
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import time
import uuid
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from .batch_job import (
    _TCP_SCHEMES,
    CONNECT_TIMEOUT_S,
    REPO_ROOT,
    SchedulerUnreachable,
    Task,
    _trim,
    parse_scheduler,
)
from .batch_task import run_task


def _worker_environment() -> None:
    """Make the repository importable in spawned workers (they start a fresh interpreter)."""
    paths = os.environ.get("PYTHONPATH", "").split(os.pathsep)
    if str(REPO_ROOT) not in paths:
        os.environ["PYTHONPATH"] = os.pathsep.join(p for p in (str(REPO_ROOT), *paths) if p)


def _worker_loop(conn: Any) -> None:
    """A worker process: run each task received on ``conn`` and send its result back; None ends."""
    while True:
        try:
            item = conn.recv()
        except EOFError:
            return
        if item is None:
            return
        conn.send(run_task(item))


@dataclass
class _Slot:
    process: Any
    conn: Any
    index: int | None = None
    deadline: float | None = None
    started: float = 0.0


@dataclass
class _Pending:
    index: int
    attempts: list[dict[str, Any]] = field(default_factory=list)


def _run_pool(
    payload: list[dict[str, Any]],
    workers: int,
    timeout: float | None,
    retries: int,
    finished: Callable[[int, dict[str, Any]], None],
    note: Callable[[str], None],
) -> None:
    """Run tasks on ``workers`` processes; a dead or timed-out worker is replaced and its task retried.

    Only the lost worker's own task is affected: it goes back to the queue (at most ``retries``
    times) with the attempt recorded; every other task keeps running where it is.
    """
    import multiprocessing
    from multiprocessing.connection import wait

    _worker_environment()
    context = multiprocessing.get_context("spawn")
    queue = [_Pending(i) for i in range(len(payload))]
    slots: list[_Slot] = []

    def spawn() -> _Slot:
        parent, child = context.Pipe()
        process = context.Process(target=_worker_loop, args=(child,), daemon=True)
        process.start()
        child.close()
        return _Slot(process, parent)

    def lost(slot: _Slot, reason: str, pending: dict[int, _Pending]) -> None:
        entry = pending.pop(slot.index)  # type: ignore[arg-type]
        item = payload[entry.index]
        entry.attempts.append({"pid": slot.process.pid, "host": socket.gethostname(), "outcome": reason})
        name = f"{Path(item['blend']).name} frame {item['frame']}"
        if len(entry.attempts) <= retries:
            note(f"{name}: {reason}; retrying on a fresh worker ({len(entry.attempts)}/{retries})")
            queue.insert(0, entry)
        else:
            finished(
                entry.index,
                {
                    "task": item,
                    "ok": False,
                    "error": f"{reason} ({len(entry.attempts)} attempt(s), --retries {retries})",
                    "outputs": {},
                    "written": [],
                    "warnings": [],
                    "seconds": {},
                    "attempts": entry.attempts,
                },
            )

    pending: dict[int, _Pending] = {}
    try:
        slots = [spawn() for _ in range(min(workers, len(payload)))]
        while queue or pending:
            for slot in slots:
                if slot.index is None and queue:
                    entry = queue.pop(0)
                    slot.index, slot.started = entry.index, time.monotonic()
                    slot.deadline = slot.started + timeout if timeout else None
                    pending[entry.index] = entry
                    slot.conn.send(payload[entry.index])
            now = time.monotonic()
            deadlines = [s.deadline - now for s in slots if s.index is not None and s.deadline]
            ready = wait(
                [s.conn for s in slots] + [s.process.sentinel for s in slots],
                timeout=max(0.0, min(deadlines)) if deadlines else None,
            )
            for i, slot in enumerate(list(slots)):
                if slot.conn in ready and slot.index is not None:
                    try:
                        result = slot.conn.recv()
                    except (EOFError, OSError):
                        result = None
                    if result is not None:
                        entry = pending.pop(slot.index)
                        result["attempts"] = [
                            *entry.attempts,
                            {
                                "pid": result.get("pid"),
                                "host": result.get("host"),
                                "outcome": "ok" if result["ok"] else "failed",
                            },
                        ]
                        finished(entry.index, result)
                        slot.index = slot.deadline = None
                        continue
                expired = slot.deadline is not None and time.monotonic() >= slot.deadline
                if slot.process.sentinel in ready or expired or (slot.conn in ready and slot.index is None):
                    if expired and slot.process.is_alive():
                        slot.process.kill()
                    slot.process.join(5)
                    if slot.index is not None:
                        reason = (
                            f"timed out after --timeout {timeout:g} s"
                            if expired
                            else f"worker process died (exit code {slot.process.exitcode})"
                        )
                        lost(slot, reason, pending)
                    slot.conn.close()
                    slots[i] = spawn() if (queue or pending) else slots[i]
                    if slots[i] is slot:
                        slot.index = slot.deadline = None
    finally:
        for slot in slots:
            if slot.index is not None and slot.process.is_alive():
                slot.process.kill()  # interrupted while busy: its task is not finished, stop it now
                continue
            try:
                slot.conn.send(None)
            except (OSError, ValueError):
                pass
        for slot in slots:
            slot.process.join(10)
            if slot.process.is_alive():
                slot.process.kill()
                slot.process.join(5)


def run_tasks(
    tasks: Sequence[Task],
    *,
    workers: int = 1,
    scheduler: str | None = None,
    dask_local: int = 0,
    timeout: float | None = None,
    retries: int = 2,
    on_result: Callable[[dict[str, Any]], None] | None = None,
    note: Callable[[str], None] = lambda text: None,
    connect_timeout: float = CONNECT_TIMEOUT_S,
    info: dict[str, Any] | None = None,
) -> list[dict[str, Any]]:
    """Run tasks in this process, in ``workers`` processes, or on a Dask cluster; results in task order.

    Args:
        tasks: the tasks (output paths already resolved).
        workers: worker processes; 1 without ``timeout`` runs in this process.
        scheduler: a Dask scheduler address (``tcp://host:port``).
        dask_local: start a Dask cluster of this many workers on loopback.
        timeout: seconds per task before its worker is ended and the task retried.
        retries: how many times a task whose worker was lost is run again (with ``scheduler`` the
            scheduler's own ``distributed.scheduler.allowed-failures`` decides instead).
        on_result: called with each result as it arrives.
        note: receives one-line messages (retries) for the user.
        connect_timeout: seconds allowed to reach ``scheduler``.
        info: receives facts about the executor for the report.

    Raises:
        SchedulerUnreachable: ``scheduler`` did not answer within ``connect_timeout``.
    """
    payload = [asdict(t) for t in tasks]
    results: list[dict[str, Any] | None] = [None] * len(tasks)

    def finished(index: int, result: dict[str, Any]) -> None:
        results[index] = result
        if on_result is not None:
            on_result(result)

    if scheduler or dask_local:
        _run_dask(payload, scheduler, dask_local, retries, finished, connect_timeout, info)
    elif workers > 1 or timeout:
        _run_pool(payload, workers, timeout, retries, finished, note)
    else:
        for i, item in enumerate(payload):
            result = run_task(item)
            result["attempts"] = [
                {"pid": result["pid"], "host": result["host"], "outcome": "ok" if result["ok"] else "failed"}
            ]
            finished(i, result)
    return [r for r in results if r is not None]


def _failure(item: dict[str, Any], error: BaseException) -> dict[str, Any]:
    """A failure record for a task whose worker could not return a result."""
    return {
        "task": item,
        "ok": False,
        "error": f"worker failed: {type(error).__name__}: {_trim(error)}",
        "outputs": {},
        "written": [],
        "warnings": [],
        "seconds": {},
    }


def _attempts_from_markers(item: dict[str, Any], result: dict[str, Any]) -> list[dict[str, Any]]:
    """Every attempt of a Dask task, from the markers its runs left in the shared attempt directory.

    An attempt whose marker records an end is reported with its own outcome; only one without an
    end — its process was lost mid-task — is "worker lost before the task finished". The attempt
    that produced ``result`` gets the result's outcome even if its end was not recorded yet.
    """
    directory = item.get("attempt_dir")
    task = Task(**item)
    markers = []
    if directory and Path(directory).is_dir():
        for path in Path(directory).glob(f"{task.key}.*"):
            try:
                markers.append(json.loads(path.read_text()))
            except (OSError, ValueError):
                continue
    markers.sort(key=lambda m: m.get("start", 0.0))
    attempts = []
    for marker in markers:
        final = marker.get("pid") == result.get("pid") and marker.get("host") == result.get("host")
        if final:
            outcome = "ok" if result["ok"] else "failed"
        else:
            outcome = marker.get("outcome") or "worker lost before the task finished"
        attempts.append({"pid": marker.get("pid"), "host": marker.get("host"), "outcome": outcome})
    return attempts


def probe_scheduler(address: str, timeout: float) -> None:
    """Reach the Dask scheduler at ``address`` within ``timeout`` seconds (TCP, then Dask's handshake).

    Raises:
        SchedulerUnreachable: naming the address, the time allowed and the reason.
    """
    scheme, host, port = parse_scheduler(address)
    if scheme in _TCP_SCHEMES:
        try:
            with socket.create_connection((host, port), timeout=timeout):
                pass
        except OSError as error:
            reason = "no answer" if isinstance(error, TimeoutError) else (error.strerror or str(error))
            raise SchedulerUnreachable(
                f"--scheduler: cannot connect to {address} within {timeout:g} s ({reason}); is "
                "`dask scheduler` running there? (--connect-timeout sets the time allowed)"
            ) from None
    # Dask's own handshake, bounded here: Client() and comm.connect() wait forever on a server that
    # accepts the connection and never answers.
    import asyncio

    from distributed.comm import connect

    async def handshake() -> None:
        comm = await asyncio.wait_for(connect(address), timeout)
        await comm.close()

    try:
        asyncio.run(handshake())
    except (OSError, TimeoutError) as error:
        reason = _trim(error).splitlines()[0] if str(error).strip() else "no Dask handshake"
        raise SchedulerUnreachable(
            f"--scheduler: {address} did not answer as a Dask scheduler within {timeout:g} s ({reason})"
        ) from None


def _connect(address: str, timeout: float) -> Any:
    """A Dask client of the scheduler at ``address``.

    Raises:
        SchedulerUnreachable: no Dask scheduler answered within ``timeout`` seconds.
    """
    from distributed import Client

    try:
        return Client(address, timeout=timeout, set_as_default=False)
    except (OSError, TimeoutError) as error:
        reason = _trim(error).splitlines()[0] if str(error).strip() else type(error).__name__
        raise SchedulerUnreachable(
            f"--scheduler: {address} did not answer as a Dask scheduler within {timeout:g} s ({reason})"
        ) from None


def _run_dask(
    payload: list[dict[str, Any]],
    scheduler: str | None,
    local_workers: int,
    retries: int,
    finished: Callable[[int, dict[str, Any]], None],
    connect_timeout: float = CONNECT_TIMEOUT_S,
    info: dict[str, Any] | None = None,
) -> None:
    """Run the tasks on a Dask cluster; each result is released as soon as it has arrived.

    A finished task's result (its file is written and read back by then) is released at once, so
    the scheduler forgets it: a worker lost later cannot make it compute the frame again. Whatever
    has not finished is cancelled before returning. ``info`` receives facts for the report
    (the scheduler's ``allowed-failures``).
    """
    import dask
    from distributed import Client, LocalCluster, as_completed

    _worker_environment()
    cluster = None
    if scheduler is None:
        # A lost worker's task is rescheduled by the scheduler until it has killed this many workers.
        with dask.config.set({"distributed.scheduler.allowed-failures": retries}):
            cluster = LocalCluster(
                n_workers=local_workers,
                threads_per_worker=1,
                processes=True,
                host="127.0.0.1",
                dashboard_address=None,
            )
    try:
        client = _connect(scheduler, connect_timeout) if scheduler else Client(cluster)
        with client:
            if info is not None:

                def allowed_failures(dask_scheduler: Any = None) -> int:  # runs on the scheduler
                    return int(dask_scheduler.allowed_failures)

                with contextlib.suppress(Exception):  # informative only
                    info["allowed_failures"] = client.run_on_scheduler(allowed_failures)
            keys = [f"batch-{Task(**item).key}-{uuid.uuid4().hex[:6]}" for item in payload]
            futures = client.map(run_task, payload, key=keys, pure=False)
            index = {f.key: i for i, f in enumerate(futures)}
            live = {f.key: f for f in futures}
            arriving = as_completed(futures, loop=client.loop)
            del futures
            try:
                for future in arriving:
                    i = index[future.key]
                    try:
                        result = future.result()
                    except Exception as error:
                        result = _failure(payload[i], error)
                    # Release the result now: a finished frame is never computed again.
                    live.pop(future.key, None)
                    future.release()
                    result["attempts"] = _attempts_from_markers(payload[i], result)
                    finished(i, result)
            finally:
                if live:
                    client.cancel(list(live.values()), force=True)
                    live.clear()
    finally:
        if cluster is not None:
            cluster.close()
