"""The task layer (yarnfit.tasks): dependencies, failures kept per task, the cache, interrupts,
and the same graph on a local pool and on a Dask cluster."""

import operator
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

import yarnfit

from yarnfit.outputs import check_writable, write_atomically
from yarnfit.tasks import DaskBackend, LocalPool, Result, SkippedTask, Task, TaskCache, one_core, run_tasks

# A stopped pool's workers must be gone this soon (the interrupt budget is 2 s in all).
STOP_SECONDS = 2.0


def square(x):
    return x * x


def fail(message):
    raise ValueError(message)


def record_call(folder, name, value):
    """Leave a file per call (the calls run in worker processes), return value."""
    with open(os.path.join(folder, f"{name}-{time.monotonic_ns()}"), "w"):
        pass
    return value


def graph(folder=None):
    """a = 3, b = 4, c = a² + b², d fails, e needs d, f needs e; with ``folder`` a and b count calls."""
    a = Task("a", record_call, (folder, "a", 3)) if folder else Task("a", operator.add, (1, 2))
    b = Task("b", record_call, (folder, "b", 4)) if folder else Task("b", operator.add, (2, 2))
    return [
        a, b,
        Task("a2", square, (Result("a"),)),
        Task("b2", square, (Result("b"),)),
        Task("c", operator.add, (Result("a2"), Result("b2"))),
        Task("d", fail, ("no yarn today",), label="row 4"),
        Task("e", square, (Result("d"),)),
        Task("f", square, (Result("e"),)),
    ]


@pytest.mark.parametrize("workers", [1, 2])
def test_dependencies_and_failures_on_a_local_pool(workers):
    seen = []
    with LocalPool(workers) as pool:
        out = run_tasks(graph(), pool, on_done=lambda task, outcome, done, total: seen.append((task.key, done, total)))
    assert out["c"] == 25
    assert isinstance(out["d"], ValueError) and str(out["d"]) == "no yarn today"
    # The failure stays d's: its dependents are skipped naming it, the rest completed.
    assert isinstance(out["e"], SkippedTask) and "row 4" in str(out["e"]) and "no yarn today" in str(out["e"])
    assert isinstance(out["f"], SkippedTask) and "no yarn today" in str(out["f"])
    assert sorted(k for k, _, _ in seen) == sorted(out) and [d for _, d, _ in seen] == list(range(1, 9))
    assert all(total == 8 for _, _, total in seen)


def threads_in_use() -> tuple[int, int]:
    """``(numba, blas)``: the threads Numba's parallel kernels and the most threads any BLAS loaded
    in this process would use."""
    import numba
    from threadpoolctl import threadpool_info

    blas = max((pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas"), default=1)
    return numba.get_num_threads(), blas


@pytest.mark.parametrize("workers", [1, 2])
def test_a_task_runs_on_one_core_and_leaves_the_caller_s_threads_alone(workers):
    import numba
    from threadpoolctl import threadpool_limits

    # The caller may thread over every core (as numpy's BLAS and Numba do): a task must not. (On a
    # one-core machine Numba has one thread to begin with; BLAS is still set to two here.)
    cores = numba.config.NUMBA_NUM_THREADS
    numba.set_num_threads(cores)
    with threadpool_limits(limits=2, user_api="blas"):
        before = threads_in_use()
        assert before == (cores, 2)  # numpy's BLAS is loaded here
        with LocalPool(workers) as pool:
            out = run_tasks([Task(k, threads_in_use, ()) for k in range(2 * workers)], pool)
        assert set(out.values()) == {(1, 1)}
        assert threads_in_use() == before
        with one_core():
            assert threads_in_use() == (1, 1)
        assert threads_in_use() == before


def test_longest_ready_tasks_start_first():
    order = []
    tasks = [Task(i, operator.mul, (i, 1), cost=c) for i, c in enumerate([1.0, 5.0, 3.0, 5.0])]
    run_tasks(tasks, LocalPool(1), on_done=lambda task, *_: order.append(task.key))
    assert order == [1, 3, 2, 0]  # by cost, ties in the given order


def test_bad_graphs_are_refused():
    with pytest.raises(ValueError, match="two tasks have the key 'a'"):
        run_tasks([Task("a", square, (1,)), Task("a", square, (2,))], LocalPool(1))
    with pytest.raises(ValueError, match="needs 'z', which is not in the graph"):
        run_tasks([Task("a", square, (Result("z"),))], LocalPool(1))
    with pytest.raises(ValueError, match="cycle"):
        run_tasks([Task("a", square, (Result("b"),)), Task("b", square, (Result("a"),))], LocalPool(1),
                  cache=TaskCache("unused"))


def test_the_cache_skips_what_it_has_and_recomputes_what_changed(tmp_path):
    calls = tmp_path / "calls"
    calls.mkdir()
    cache = TaskCache(tmp_path / "cache")
    with LocalPool(2) as pool:
        first = run_tasks(graph(str(calls)), pool, cache=cache)
    assert first["c"] == 25 and len(os.listdir(calls)) == 2
    # Results and the inputs' own failures (d's ValueError) are cached, whole files only; skips
    # are not (they follow from d).
    assert len(list((tmp_path / "cache").glob("*.pkl"))) == 6
    assert not list((tmp_path / "cache").glob("*.part"))
    with LocalPool(2) as pool:
        again = run_tasks(graph(str(calls)), pool, cache=cache)
    assert again["c"] == 25 and len(os.listdir(calls)) == 2  # nothing recomputed
    assert isinstance(again["d"], ValueError) and isinstance(again["f"], SkippedTask)
    # Wanting only c: its cached result is loaded, nothing upstream is run or loaded.
    assert run_tasks(graph(str(calls)), LocalPool(1), cache=cache, wanted=["c"]) == {"c": 25}
    changed = [Task("a", record_call, (str(calls), "a", 5)) if t.key == "a" else t for t in graph(str(calls))]
    with LocalPool(2) as pool:
        third = run_tasks(changed, pool, cache=cache)
    # a changed: a, a2 and c ran again (a's key changed, and with it its dependents'); b did not.
    assert third["c"] == 41 and sorted(n.split("-")[0] for n in os.listdir(calls)) == ["a", "a", "b"]


def test_a_failure_of_the_machine_is_not_cached(tmp_path):
    cache = TaskCache(tmp_path)
    tasks = [Task("lost", open, ("/nonexistent/x",))]  # an OSError: the machine's, not the inputs'.
    assert isinstance(run_tasks(tasks, LocalPool(1), cache=cache)["lost"], OSError)
    assert list(tmp_path.iterdir()) == []


def test_a_stopped_pool_leaves_no_worker_behind():
    pool = LocalPool(2)
    futures = {pool.submit(time.sleep, (30,)) for _ in range(4)}
    workers = list(pool._executor()._processes.values())
    time.sleep(0.5)  # the workers have started their sleeps
    start = time.perf_counter()
    pool.stop()
    assert time.perf_counter() - start < STOP_SECONDS
    for process in workers:
        process.join(STOP_SECONDS)
        assert not process.is_alive()
    assert futures


def test_a_dask_cluster_runs_the_same_graph():
    with DaskBackend(workers=2) as cluster:
        out = run_tasks(graph(), cluster)
    assert out["c"] == 25
    assert isinstance(out["d"], ValueError) and isinstance(out["f"], SkippedTask)


def test_outputs_are_checked_before_and_written_whole(tmp_path):
    target = tmp_path / "a" / "b" / "out.json"
    assert check_writable(target, "material file") == target
    assert not (tmp_path / "a").exists()  # checking creates nothing
    with pytest.raises(OSError, match="it is a directory"):
        check_writable(tmp_path, "material file")
    (tmp_path / "file").write_text("x")
    with pytest.raises(OSError, match="is not a directory"):
        check_writable(tmp_path / "file" / "out.json", "material file")
    if os.geteuid() != 0:  # root writes anywhere
        locked = tmp_path / "locked"
        locked.mkdir(mode=0o500)
        with pytest.raises(OSError, match="not writable"):
            check_writable(locked / "out.json", "material file")
    write_atomically(target, "whole")
    assert target.read_text() == "whole" and os.listdir(target.parent) == ["out.json"]


def checkout_env() -> dict:
    """The environment for ``python -m yarnfit.cli`` in a subprocess with the yarnfit under test
    first on the path, wherever the installed one is."""
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(Path(yarnfit.__file__).parents[1]),
                                                         os.environ.get("PYTHONPATH", "")])}


def default_sigint():
    """In the child before exec: SIGINT back to its default. A shell without job control (CI
    running in the background) starts its commands with SIGINT ignored, which they inherit, and
    Python then installs no KeyboardInterrupt handler: the test would send a signal nobody hears."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _children(pid):
    return subprocess.run(["pgrep", "-P", str(pid)], capture_output=True, text=True).stdout.split()


def test_sigint_stops_a_fit_during_its_samples(tmp_path):
    """The issue's check: SIGINT to `yarnfit fit` while it solves samples exits 130 within 2 s,
    one line and no traceback, no output file, no worker process left."""
    # A polyester satin: its samples take ~0.5 s each on one core, the slowest several seconds, so
    # two workers are still solving at the first progress line (a plain weave's 58 samples had all
    # finished by then once the solver was fast enough).
    command = [sys.executable, "-m", "yarnfit.cli", "fit", "--fiber", "polyester", "--pattern", "satin-5", "--gsm",
               "100", "--counts", "60x35", "--samples", "58", "--workers", "2", "-o", str(tmp_path / "satin.json"),
               "--rerun", str(tmp_path / "satin.rrd")]
    fit = subprocess.Popen(command, stderr=subprocess.PIPE, text=True, cwd=tmp_path, env=checkout_env(),
                           preexec_fn=default_sigint)
    seen = []
    for line in fit.stderr:
        seen.append(line)
        # Off a terminal progress comes every 2 s: the 58 samples outlast that, so the first line
        # lands while workers are still solving (16 samples could all finish before it).
        done = re.match(r"samples (\d+)/(\d+)", line)
        if done:
            assert int(done[1]) < int(done[2]), "the samples ended before the first progress line"
            break
    else:
        pytest.fail(f"the fit ended before its samples: {''.join(seen)[-500:]}")
    workers = _children(fit.pid)
    assert workers, "no worker processes"
    start = time.perf_counter()
    fit.send_signal(signal.SIGINT)
    rest = fit.stderr.read()
    assert fit.wait(timeout=10) == 130
    assert time.perf_counter() - start < STOP_SECONDS
    assert rest.strip() == "yarnfit fit: interrupted" and "Traceback" not in rest, rest
    assert os.listdir(tmp_path) == []
    time.sleep(0.2)
    assert [w for w in workers if os.path.exists(f"/proc/{w}")] == []
