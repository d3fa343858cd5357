"""Many samples solved in parallel, grouped into tasks: each bend family and sign as a path of
growing curvature (each search started from the gentler bend's answer, :mod:`.bend`), with
friction each membrane family and sign as a load path from rest (:mod:`.loading`), every other
sample alone. This module is the one place a design's samples are grouped
(:func:`sample_groups`) and a group is solved (:func:`solve_group`); a catalogue's tasks use both.
"""

from __future__ import annotations

import math
from typing import Callable, Hashable, Sequence

from ..engine import QuasiStaticOptions
from ..relax import RelaxedRepeat
from ..samples import SampleResult, SampleSpec
from ..tasks import Backend, LocalPool, Task, run_tasks
from .bend import _solve_bend_path
from .equilibrium import MAX_ITERATIONS
from .loading import loading_path_samples
from .sample import _expected_cost, solve_sample

__all__ = ["group_tasks", "sample_groups", "solve_group", "solve_loading_samples", "solve_samples"]


def _path_key(spec: SampleSpec, friction: bool) -> tuple | None:
    """The path a sample belongs to, ``(family, positive)``, or ``None`` for one solved alone:
    a bend (not the unbent reference) always; a membrane sample (not the undeformed reference)
    with ``friction``."""
    if spec.parameter == 0.0 or (spec.is_membrane and not friction):
        return None
    return spec.family, spec.parameter > 0.0


def sample_groups(specs: Sequence[SampleSpec], friction: bool = False) -> list[tuple[int, ...]]:
    """The indices of ``specs`` each task solves, in the order it solves them: a path per family
    and sign (:func:`_path_key`) in order of growing magnitude, then every other sample alone, in
    the order of ``specs``. Which samples form a path depends only on their families and signs, not
    on the magnitudes (a catalogue groups its design before the repeat is relaxed)."""
    paths: dict[tuple, list[int]] = {}
    alone: list[tuple[int, ...]] = []
    for i, spec in enumerate(specs):
        key = _path_key(spec, friction)
        if key is None:
            alone.append((i,))
        else:
            paths.setdefault(key, []).append(i)
    ordered = [tuple(sorted(indices, key=lambda i: abs(specs[i].parameter))) for indices in paths.values()]
    return ordered + alone


def solve_group(relaxed: RelaxedRepeat, specs: Sequence[SampleSpec], coefficient: float | None = None,
                options: QuasiStaticOptions | None = None) -> list[SampleResult]:
    """The samples of one group of :func:`sample_groups` (``specs`` in its order), solved: a bend
    path (:func:`~yarnfit.homogenize.bend._solve_bend_path`), a frictional load path with friction
    ``coefficient`` μ (:func:`~yarnfit.homogenize.loading_path_samples`; ``None``: frictionless
    samples), or one sample (:func:`~yarnfit.homogenize.solve_sample`).

    Raises:
        ValueError: ``specs`` are not one group of :func:`sample_groups`.
    """
    keys = {_path_key(spec, coefficient is not None) for spec in specs}
    if not specs or len(keys) != 1 or (None in keys and len(specs) != 1):
        raise ValueError(f"samples {[f'{s.family} {s.parameter:+.3g}' for s in specs]} are not one group of "
                         "a design (one sample, or one path of a family and sign)")
    if None in keys:
        return [solve_sample(relaxed, specs[0], options)]
    options = options or QuasiStaticOptions(max_iterations=MAX_ITERATIONS)
    if not specs[0].is_membrane:
        return _solve_bend_path(relaxed, specs, options)
    return loading_path_samples(relaxed, specs[0].family, [spec.parameter for spec in specs], coefficient)


def group_tasks(relaxed, specs: Sequence[SampleSpec], groups: Sequence[tuple[int, ...]],
                coefficient: float | None = None, key: Callable[[int], Hashable] = lambda j: j,
                label: str = "") -> list[Task]:
    """One :class:`~yarnfit.tasks.Task` per group: ``solve_group(relaxed, its specs, coefficient)``
    keyed ``key(j)`` for ``groups[j]``, ranked so that the longest start first (paths, then the
    uniaxial searches, 5–15 solves each, then the membrane samples by strain). ``relaxed`` may be a
    :class:`~yarnfit.tasks.Result` placeholder."""
    order = sorted(range(len(groups)), key=lambda j: (len(groups[j]), max(_expected_cost(specs[i]) for i in groups[j])),
                   reverse=True)
    rank = {j: len(groups) - r for r, j in enumerate(order)}
    tasks = []
    for j, group in enumerate(groups):
        what = (f"sample {group[0] + 1}/{len(specs)} ({specs[group[0]].family} {specs[group[0]].parameter:+.3g})"
                if len(group) == 1 else
                f"path of {len(group)} samples ({specs[group[0]].family} {'+' if specs[group[0]].parameter > 0 else '-'})")
        tasks.append(Task(key(j), solve_group, (relaxed, [specs[i] for i in group], coefficient), cost=rank[j],
                          label=f"{label}{what}"))
    return tasks


def solve_samples(
    relaxed: RelaxedRepeat,
    specs: Sequence[SampleSpec],
    workers: int | None = None,
    on_sample: Callable[[int, int, SampleResult], None] | None = None,
    backend: Backend | None = None,
    coefficient: float | None = None,
) -> list[SampleResult]:
    """Solve every sample on ``backend`` (default: a :class:`~yarnfit.tasks.LocalPool` of
    ``workers`` processes, every core by default; 1 runs in this process), grouped by
    :func:`sample_groups` (with friction ``coefficient`` μ its membrane samples on load paths;
    ``None``: frictionless). ``on_sample(done, total, result)`` is called as each sample is known.
    Results come back in the order of ``specs``.

    A group whose solve raises makes this raise it (after the others finished); Ctrl-C stops the
    workers and raises ``KeyboardInterrupt`` (:mod:`yarnfit.tasks`)."""
    groups = sample_groups(specs, coefficient is not None)
    if backend is None:
        # One task per group: a design of three bend paths needs no more than three workers.
        with LocalPool(workers, tasks=len(groups)) as pool:
            return _solve_groups(relaxed, specs, groups, pool, on_sample, coefficient)
    return _solve_groups(relaxed, specs, groups, backend, on_sample, coefficient)


def _solve_groups(relaxed: RelaxedRepeat, specs: Sequence[SampleSpec], groups: list[tuple[int, ...]],
                  backend: Backend, on_sample: Callable[[int, int, SampleResult], None] | None,
                  coefficient: float | None) -> list[SampleResult]:
    """:func:`solve_samples` on ``backend`` with its ``groups`` (:func:`sample_groups`) made."""
    results: list[SampleResult | None] = [None] * len(specs)
    known = 0

    def done(task, outcome, count, total):
        nonlocal known
        if isinstance(outcome, BaseException):
            return
        for i, sample in zip(groups[task.key], outcome):
            results[i] = sample
            known += 1
            if on_sample is not None:
                on_sample(known, len(specs), sample)

    outcomes = run_tasks(group_tasks(relaxed, specs, groups, coefficient), backend, on_done=done)
    for j in range(len(groups)):
        if isinstance(outcomes[j], BaseException):
            raise outcomes[j]
    return results


def solve_loading_samples(relaxed: RelaxedRepeat, specs: Sequence[SampleSpec], coefficient: float,
                          workers: int | None = None,
                          on_sample: Callable[[int, int, SampleResult], None] | None = None,
                          backend: Backend | None = None) -> list[SampleResult]:
    """:func:`solve_samples` with the membrane samples on frictional load paths with friction
    ``coefficient`` μ (:func:`~yarnfit.homogenize.loading_path_samples`, one task per family and
    sign); the bends, the reference samples as without friction."""
    if not (math.isfinite(coefficient) and coefficient >= 0.0):
        raise ValueError(f"friction coefficient must be finite and non-negative, got {coefficient!r}")
    return solve_samples(relaxed, specs, workers, on_sample, backend, coefficient)
