"""Independent tasks run in parallel: one layer for every long computation yarnfit does.

A fit solves tens of yarn-level samples; a catalogue relaxes, samples, fits, exports and validates
many fabrics. Both hand this module a graph of :class:`Task` s (a function, its arguments, the
tasks whose results it takes) and a :class:`Backend` that runs them:

* :class:`LocalPool` (the default): worker processes on this machine (``fork`` where the platform
  has it), or this process alone with one worker;
* :class:`DaskBackend`: a ``dask.distributed`` cluster, a :class:`distributed.LocalCluster` started
  for the run or an existing scheduler (``tcp://host:port``) that ``dask scheduler`` / ``dask
  worker`` processes serve.

:func:`run_tasks` submits each task once its dependencies are done (their results are passed as
the arguments the task names by :class:`Result`), longest first among those ready, and so behaves
the same on either backend:

* **results cached** (:class:`TaskCache`) by a hash of the task's function, arguments and the yarnfit
  version, written whole (temporary file, then rename), with the inputs' own failures
  (:data:`CACHED_FAILURES`): a rerun, or a run after an interrupted one, recomputes nothing it
  already has, and loads only what the wanted tasks need;
* **a failure stays one task's**: its exception is kept, the tasks that needed its result are
  skipped with :class:`SkippedTask` naming it, every other task still runs;
* **progress** through ``on_done(task, outcome, done, total)`` as each task finishes;
* **interrupts**: ``KeyboardInterrupt`` (Ctrl-C) cancels every queued task, stops the workers
  (local ones are terminated; a cluster's futures are cancelled and a cluster started for the run
  is closed) and propagates, within a second or so.

Worker processes ignore SIGINT: Ctrl-C in a terminal reaches the whole process group, and the
parent alone decides what stops (the workers would otherwise each print a traceback). A task runs
on one core (:func:`one_core`): its Numba kernels and BLAS (numpy's, scipy's) on one thread, as on
a Dask worker (``distributed.nanny.pre-spawn-environ``), because a yarn-level solve's dense algebra is small (a
periodic repeat's constraint rows, 30 × 2400) and BLAS threads beside the other workers only
contend for the cores.
"""

from __future__ import annotations

import hashlib
import heapq
import multiprocessing
import os
import pickle
import signal
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, field, fields, is_dataclass
from pathlib import Path
from typing import Any, Callable, Hashable, Iterable, Sequence

import numba
import numpy as np
from threadpoolctl import threadpool_limits

from . import __version__
from .checks import error_line
from .outputs import write_atomically

__all__ = ["Backend", "DaskBackend", "LocalPool", "Result", "SkippedTask", "Task", "TaskCache", "ignore_sigint",
           "make_backend", "one_core", "run_tasks"]


@dataclass(frozen=True)
class Result:
    """Placeholder for the result of the task ``key`` among another task's arguments."""

    key: Hashable


@dataclass(frozen=True, eq=False)
class Task:
    """One unit of work: ``function(*args)``, a module-level function (it is pickled to workers)
    whose arguments may contain :class:`Result` placeholders, replaced by those tasks' results.

    Attributes:
        key: unique in the graph (any hashable; shown in messages).
        function: what runs.
        args: its positional arguments.
        cost: larger runs earlier among the tasks ready at once (an estimate, any units).
        cached: cache the result (:class:`TaskCache`); the cache key hashes ``function``'s module
            and name, ``args`` (the dependencies by their own cache keys) and the yarnfit version.
        label: what it is, for progress and failure messages (default: the key).
    """

    key: Hashable
    function: Callable
    args: tuple = ()
    cost: float = 0.0
    cached: bool = True
    label: str = ""

    @property
    def dependencies(self) -> list[Hashable]:
        return [a.key for a in self.args if isinstance(a, Result)]

    def describe(self) -> str:
        return self.label or str(self.key)


class SkippedTask(RuntimeError):
    """A task not run because a task it needs failed (or was skipped)."""


class TaskCache:
    """Results on disk under ``directory``, one pickle per task, named by the task's cache key.

    Pickles are this installation's own files: the cache is a private working directory of
    yarnfit, not a format to exchange (do not point it at files from elsewhere).
    """

    def __init__(self, directory: str | os.PathLike):
        self.directory = Path(directory)

    def path(self, key: str) -> Path:
        return self.directory / f"{key}.pkl"

    def load(self, key: str) -> tuple[bool, Any]:
        """``(found, value)``; an unreadable entry (a format from another version) counts as absent."""
        path = self.path(key)
        if not path.exists():
            return False, None
        try:
            with open(path, "rb") as f:
                return True, pickle.load(f)
        except Exception:  # noqa: BLE001 - any unreadable entry is recomputed, and then replaced
            return False, None

    def store(self, key: str, value: Any) -> None:
        write_atomically(self.path(key), pickle.dumps(value, protocol=pickle.HIGHEST_PROTOCOL))


def cache_key(task: Task, dependency_keys: dict[Hashable, str]) -> str:
    """Hex SHA-256 of the task's function, arguments (dependencies by their cache keys) and the
    yarnfit version: any change of input or code version is a new key."""
    args = [["result", dependency_keys[a.key]] if isinstance(a, Result) else _canonical(a) for a in task.args]
    payload = repr([__version__, task.function.__module__, task.function.__qualname__, args])
    return hashlib.sha256(payload.encode("utf-8")).hexdigest()


def _canonical(value):
    """A representation of an argument that depends on its value only: a dataclass by its fields
    (not by what its cached properties happen to hold), mappings by sorted keys, floats exactly
    (``float.hex``), arrays by dtype, shape and bytes; anything else by its pickle."""
    if value is None or isinstance(value, (bool, int, str)):
        return value
    if isinstance(value, float):
        return value.hex()
    if isinstance(value, (tuple, list)):
        return [type(value).__name__, [_canonical(v) for v in value]]
    if isinstance(value, dict):
        return ["dict", sorted(([_canonical(k), _canonical(v)] for k, v in value.items()), key=repr)]
    if is_dataclass(value) and not isinstance(value, type):
        return [type(value).__module__, type(value).__qualname__,
                [[f.name, _canonical(getattr(value, f.name))] for f in fields(value)]]
    if isinstance(value, np.ndarray):
        return ["ndarray", str(value.dtype), list(value.shape), hashlib.sha256(np.ascontiguousarray(value)).hexdigest()]
    if isinstance(value, np.generic):
        return _canonical(value.item())
    return ["pickle", hashlib.sha256(pickle.dumps(value, protocol=4)).hexdigest()]


# -- backends -------------------------------------------------------------------------------------


@contextmanager
def one_core():
    """Compute on one core inside the block: Numba's parallel kernels and BLAS (numpy's, scipy's)
    on one thread each, both restored after. What a task runs under, and what the validation
    scripts time their one-core figures under (with either left threading, two solves side by
    side contend for the cores)."""
    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        with threadpool_limits(limits=1, user_api="blas"):
            yield
    finally:
        numba.set_num_threads(threads)


def ignore_sigint() -> None:
    """A helper process's initializer: SIGINT ignored (Ctrl-C reaches the whole process group; the
    parent alone decides what stops, and stops its helpers itself)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


# A worker process's one core, entered by start_worker and never left (held here: a context
# manager that is garbage-collected would run its exit and restore the threads).
_WORKER_CORE = ExitStack()


def start_worker() -> None:
    """A :class:`LocalPool` worker's initializer: SIGINT ignored (:func:`ignore_sigint`) and one
    core (:func:`one_core`) for the worker's life (``fork`` copies the parent's thread pools, so the
    environment variables a spawned process reads come too late)."""
    ignore_sigint()
    _WORKER_CORE.enter_context(one_core())


class Backend:
    """Where tasks run: ``submit`` a call, ``wait_any`` of the running ones, ``stop`` everything."""

    workers: int

    @property
    def queue_depth(self) -> int:
        """Tasks kept submitted at once: two per worker, so none idles between tasks while the
        longest ready still start first."""
        return 2 * self.workers

    def submit(self, function: Callable, args: tuple):
        raise NotImplementedError

    def wait_any(self, futures: set) -> tuple[set, set]:
        raise NotImplementedError

    def stop(self) -> None:
        """Cancel what is queued and stop the workers now (interrupts)."""

    def close(self) -> None:
        """Release the workers after a finished run."""

    def __enter__(self):
        return self

    def __exit__(self, kind, value, traceback):
        if kind is not None and issubclass(kind, BaseException) and not issubclass(kind, Exception):
            self.stop()  # KeyboardInterrupt, SystemExit: stop now, wait for nothing
        else:
            self.close()
        return False


class _Done:
    """A finished in-process call, shaped like a future."""

    def __init__(self, function, args):
        try:
            with one_core():  # as in a worker
                self._value, self._error = function(*args), None
        except Exception as error:  # noqa: BLE001 - kept as the task's outcome, as a worker's would be
            self._value, self._error = None, error

    def result(self):
        if self._error is not None:
            raise self._error
        return self._value


class LocalPool(Backend):
    """``workers`` processes on this machine (default: every core), no more than ``tasks`` when
    given (the work there is to share); with one, calls run in this process, one at a time."""

    def __init__(self, workers: int | None = None, tasks: int | None = None):
        workers = (os.cpu_count() or 1) if workers is None else int(workers)
        if workers < 1:
            raise ValueError(f"workers must be at least 1, got {workers}")
        self.workers = workers if tasks is None else min(workers, max(1, int(tasks)))
        self._pool: ProcessPoolExecutor | None = None

    def _executor(self) -> ProcessPoolExecutor:
        if self._pool is None:
            # Fork where the platform has it: a spawned worker re-imports the caller's main module,
            # which re-runs any unguarded script (it hung the first trial), and forked workers
            # start at once with the parent's compiled kernels.
            method = "fork" if "fork" in multiprocessing.get_all_start_methods() else "spawn"
            self._pool = ProcessPoolExecutor(self.workers, mp_context=multiprocessing.get_context(method),
                                             initializer=start_worker)
        return self._pool

    @property
    def queue_depth(self) -> int:
        return 1 if self.workers == 1 else 2 * self.workers  # one worker: calls run as submitted

    def submit(self, function, args):
        if self.workers == 1:
            return _Done(function, args)
        return self._executor().submit(function, *args)

    def wait_any(self, futures):
        if self.workers == 1:
            return set(futures), set()
        return wait(futures, return_when=FIRST_COMPLETED)

    def stop(self) -> None:
        pool, self._pool = self._pool, None
        if pool is None:
            return
        terminate = getattr(pool, "terminate_workers", None)  # Python 3.14
        if terminate is not None:
            terminate()
            return
        # Before 3.14 the executor has no public way to stop workers that are running a task (its
        # shutdown waits for them); its process table is the one handle on them.
        for process in list((getattr(pool, "_processes", None) or {}).values()):
            process.terminate()
        pool.shutdown(wait=True, cancel_futures=True)

    def close(self) -> None:
        pool, self._pool = self._pool, None
        if pool is not None:
            pool.shutdown(wait=True)


class DaskBackend(Backend):
    """A ``dask.distributed`` cluster: the scheduler at ``address`` (``tcp://host:port``), or a
    :class:`distributed.LocalCluster` of ``workers`` single-threaded processes started here (and
    closed with the run)."""

    def __init__(self, address: str | None = None, workers: int | None = None):
        from distributed import Client, LocalCluster

        self._cluster = None
        if address is None:
            workers = (os.cpu_count() or 1) if workers is None else int(workers)
            if workers < 1:
                raise ValueError(f"workers must be at least 1, got {workers}")
            # One thread per worker: a yarn-level solve is serial Numba code, and processes keep
            # the GIL out of the way. No dashboard: nothing here serves web pages.
            self._cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                         dashboard_address=None)
            self.client = Client(self._cluster)
        else:
            try:
                self.client = Client(address, timeout="10s")
            except (OSError, TimeoutError) as error:
                raise OSError(f"cannot reach the Dask scheduler at {address}: {error}") from None
        self.workers = max(1, len(self.client.scheduler_info().get("workers", {})))
        self._futures: set = set()

    def submit(self, function, args):
        future = self.client.submit(function, *args, pure=False)
        self._futures.add(future)
        return future

    def wait_any(self, futures):
        from distributed import wait as dask_wait

        done, pending = dask_wait(list(futures), return_when="FIRST_COMPLETED")
        self._futures -= set(done)
        return set(done), set(pending)

    def stop(self) -> None:
        futures, self._futures = list(self._futures), set()
        try:
            if futures:
                self.client.cancel(futures, force=True)
        finally:
            self.close()

    def close(self) -> None:
        self.client.close()
        if self._cluster is not None:
            self._cluster.close()
            self._cluster = None


def make_backend(scheduler: str | None = None, workers: int | None = None, dask: bool = False) -> Backend:
    """The backend a command line asks for: the Dask scheduler at ``scheduler``, else a local Dask
    cluster with ``dask``, else a :class:`LocalPool` of ``workers``."""
    if scheduler is not None or dask:
        return DaskBackend(scheduler, workers)
    return LocalPool(workers)


# -- running a graph ------------------------------------------------------------------------------


@dataclass
class _Graph:
    """Tasks by key, what each still waits on, and which tasks need each."""

    tasks: dict[Hashable, Task]
    waiting_on: dict[Hashable, set] = field(default_factory=dict)
    needed_by: dict[Hashable, list] = field(default_factory=dict)

    @classmethod
    def of(cls, tasks: Iterable[Task]) -> "_Graph":
        graph = cls({})
        for task in tasks:
            if task.key in graph.tasks:
                raise ValueError(f"two tasks have the key {task.key!r}")
            graph.tasks[task.key] = task
        for task in graph.tasks.values():
            missing = [d for d in task.dependencies if d not in graph.tasks]
            if missing:
                raise ValueError(f"task {task.key!r} needs {missing[0]!r}, which is not in the graph")
            graph.waiting_on[task.key] = set(task.dependencies)
            for d in task.dependencies:
                graph.needed_by.setdefault(d, []).append(task.key)
        return graph

    def order(self) -> list[Hashable]:
        """The keys with every task after its dependencies (ValueError on a cycle)."""
        order, state = [], {}

        def visit(key):
            if state.get(key) == "done":
                return
            if state.get(key) == "open":
                raise ValueError(f"the tasks' dependencies form a cycle through {key!r}")
            state[key] = "open"
            for d in self.tasks[key].dependencies:
                visit(d)
            state[key] = "done"
            order.append(key)

        for key in self.tasks:
            visit(key)
        return order


# Failures that are the inputs' own answer and so cached like results (a relaxation that cannot
# converge, an indefinite fit, a bad pattern): rerunning would only say them again. Anything else (a
# worker lost, memory, the file system) is retried on the next run.
CACHED_FAILURES = (ValueError, ArithmeticError)


def run_tasks(
    tasks: Sequence[Task],
    backend: Backend,
    cache: TaskCache | None = None,
    on_done: Callable[[Task, object, int, int], None] | None = None,
    wanted: Iterable[Hashable] | None = None,
) -> dict[Hashable, object]:
    """Run the graph ``tasks`` on ``backend`` (see the module docstring).

    Args:
        cache: results (and :data:`CACHED_FAILURES`) by cache key (:func:`cache_key`).
        on_done: ``on_done(task, outcome, done, total)`` as each task finishes (cached ones too),
            in the parent process; ``total`` counts the tasks this run needs.
        wanted: the tasks whose outcomes the caller needs (default: all). With a cache, a task
            none of whose needed dependents must run is neither run nor loaded: a rerun of a
            finished graph loads the wanted results only.

    Returns:
        ``{key: outcome}`` for every task needed: its result, or the exception it raised (a
        :class:`SkippedTask` when a dependency failed). Failures are outcomes, not raised.

    Raises:
        ValueError: duplicate keys, a dependency that is not a task, an unknown wanted key, or a
            cycle.
        KeyboardInterrupt: after stopping the backend's work (the caller's ``with`` on the
            backend, or :meth:`Backend.stop`, ends it).
    """
    graph = _Graph.of(tasks)
    order = graph.order()
    wanted = set(graph.tasks if wanted is None else wanted)
    unknown = wanted - set(graph.tasks)
    if unknown:
        raise ValueError(f"wanted task {next(iter(unknown))!r} is not in the graph")
    keys = {}  # cache keys, in dependency order
    if cache is not None:
        for key in order:
            keys[key] = cache_key(graph.tasks[key], keys)
    # What this run needs, dependents before dependencies: a wanted task, or a dependency of a
    # needed task that must run. A needed task with a cache entry is loaded, not run.
    needed, must_run, loaded = set(), set(), {}
    for key in reversed(order):
        if key not in wanted and not any(d in must_run for d in graph.needed_by.get(key, ())):
            continue
        needed.add(key)
        if cache is not None and graph.tasks[key].cached:
            found, value = cache.load(keys[key])
            if found:
                loaded[key] = value
                continue
        must_run.add(key)
    outcomes: dict[Hashable, object] = {}
    total, finished = len(needed), [0]
    running: dict = {}  # future -> key
    # Ready tasks, longest first (ties in the order given): (-cost, index, key).
    index = {key: i for i, key in enumerate(graph.tasks)}
    ready: list = []

    def release(key) -> None:
        heapq.heappush(ready, (-graph.tasks[key].cost, index[key], key))

    def finish(key, outcome) -> None:
        outcomes[key] = outcome
        finished[0] += 1
        if on_done is not None:
            on_done(graph.tasks[key], outcome, finished[0], total)
        for dependent in graph.needed_by.get(key, ()):
            if dependent in outcomes or dependent not in must_run:
                continue
            left = graph.waiting_on[dependent]
            left.discard(key)
            if isinstance(outcome, BaseException):
                reason = outcome if isinstance(outcome, SkippedTask) else \
                    SkippedTask(f"needs {graph.tasks[key].describe()}, which failed: {_one_line(outcome)}")
                finish(dependent, reason)
            elif not left:
                release(dependent)

    def launch() -> None:
        # Keep the backend's queue depth submitted.
        while ready and len(running) < backend.queue_depth:
            _, _, key = heapq.heappop(ready)
            if key in outcomes:  # skipped meanwhile
                continue
            task = graph.tasks[key]
            args = tuple(outcomes[a.key] if isinstance(a, Result) else a for a in task.args)
            running[backend.submit(task.function, args)] = key

    for key in order:
        if key in must_run and not graph.waiting_on[key]:
            release(key)
    for key in order:  # dependencies first, so a cached failure skips its dependents
        if key in loaded and key not in outcomes:
            finish(key, loaded[key])
    launch()
    while running:
        done, _ = backend.wait_any(set(running))
        for future in done:
            key = running.pop(future)
            try:
                outcome = future.result()
            except Exception as error:  # noqa: BLE001 - a task's failure is its outcome
                outcome = error
            keep = not isinstance(outcome, BaseException) or isinstance(outcome, CACHED_FAILURES)
            if cache is not None and graph.tasks[key].cached and keep and not isinstance(outcome, SkippedTask):
                cache.store(keys[key], outcome)
            finish(key, outcome)
        launch()
    return outcomes


def _one_line(error: BaseException) -> str:
    """The failure's type and line, as a dependent's skip names it."""
    return f"{type(error).__name__}: {error_line(error)}" if str(error).strip() else type(error).__name__
