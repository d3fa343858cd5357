"""The periodic pull with the fibre's friction: the infinite fabric pulled along weft or warp from
rest as a cut strip is pulled, in lagged frictional load steps.

The samples the shell is fitted to are frictionless minimisers (the paper's homogenization): a
minimiser has no friction path. A cut strip is pulled with the fibre's friction, and a frictional
knit strip does not tend to the frictionless periodic pull as it widens (docs/design.md §3,
session 40). This is the periodic reference a frictional strip should tend to instead, so that the
two can be told apart: the strip's size from the fabric's friction.

The repeat is pulled from rest in equal load steps of at most
:data:`~yarnfit.engine.lagged.FRICTION_STRAIN_STEP`, each a lagged frictional step as a strip's
(:mod:`yarnfit.engine.friction`, IPC's lagged iterations): every loaded contact of the step's
start becomes an anchor with a frozen normal force, and each pass minimises the yarn potential
plus the anchors' friction potential over the fluctuations *and* the free transverse Green strain
E⊥, then re-anchors at its solution until the anchored normal forces settle. A pass finds E⊥ by
the frictionless search's secants (:func:`~yarnfit.homogenize.uniaxial._next_free_strain`) on the
envelope-theorem slope of that sum (:func:`~yarnfit.homogenize.equilibrium._green_slope` with the
anchors), each trial warm-started from the nearest equilibrium found.

Two things are periodic-specific. The slip of an anchor is measured from where its contact points
were at the step's start *under the tile maps of the step's start*: a pair across a tile border
has its second edge in an image whose translation grows with the macroscopic strain, and measured
with today's maps it would slip by the change of a period. And the anchors' own maps follow each
trial's tiling (:meth:`~yarnfit.engine.friction.FrictionAnchors.transformed`).

On the bias a pass is the bias search (two free strains: across the pull and the pull frame's
shear, :func:`~yarnfit.homogenize.bias._search_bias`) started from the path's last equilibrium.

What it cannot represent: as lagged friction (static above kinetic friction, contacts that appear
within a pass).
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from ..checks import positive_number
from ..engine import ConvergenceWarning, QuasiStaticOptions, QuasiStaticResult, QuasiStaticSolver, Residual
from ..engine.contact import TilingReachError
from ..engine.contact_lagrangian import ContactSet
from ..engine.friction import FrictionAnchors, anchor_contacts
from ..engine.lagged import FRICTION_STRAIN_STEP, LAG_TOLERANCE, MAX_LAG_PASSES, in_halves, load_step_count
from ..relax import RelaxedRepeat
from .bias import BIAS_ANGLE, _search_bias
from .equilibrium import MAX_ITERATIONS, _axis_change, _green_slope, _solve_from
from .pull import PULL_FAMILIES, PeriodicPull, _periodic_pull
from .surface import TiledRepeat, _form_map, tile_repeat
from .uniaxial import (FREE_STRAIN_GUESS, FREE_STRAIN_HALVINGS, FREE_STRAIN_PROBE, FREE_STRAIN_RANGE,
                       FREE_STRAIN_SOLVES, FREE_STRAIN_TOLERANCE, SEARCH_ENERGY_RTOL, SMALLEST_FREE_STRETCH,
                       _FreeStrainPoint, _next_free_strain)

__all__ = ["frictional_periodic_bias_pull", "frictional_periodic_pull", "periodic_pulls_along"]

_NO_RESIDUAL = Residual(math.nan, math.nan, math.nan, math.nan)


@dataclass(frozen=True)
class _Trial:
    """One solve of a pass at the free Green strain ``free``: the first form, the tiled repeat
    (``None`` when the solve left the tiles mapped), its result (``None`` likewise), the anchors
    with their maps at this form, and the search's point (``None`` unless converged)."""

    free: float
    form: np.ndarray
    tiled: TiledRepeat | None
    result: QuasiStaticResult | None
    anchors: FrictionAnchors | None
    point: _FreeStrainPoint | None


@dataclass(frozen=True)
class _Pass:
    """One lagged pass: the trial of least (potential + friction) chosen, every trial's Newton
    iterations, and the search's verdict (``"minimum"``, ``"upper end"`` and ``"plateau"`` are
    converged)."""

    trial: _Trial
    iterations: int
    verdict: str


def _uniaxial_form(axis: int, stretch: float, free: float) -> np.ndarray:
    """The first form ``(2, 2)`` of a pull to ``stretch`` along ``axis`` at the free Green strain
    ``free`` across it."""
    diagonal = [0.0, 0.0]
    diagonal[axis], diagonal[1 - axis] = stretch**2, 1.0 + 2.0 * free
    return np.diag(diagonal)


def _solve_trial(relaxed: RelaxedRepeat, axis: int, stretch: float, free: float, anchors: FrictionAnchors,
                 anchor_form: np.ndarray, warm: _Trial, contacts: ContactSet, options: QuasiStaticOptions) -> _Trial:
    """Solve the pull at ``free`` with ``anchors`` (their maps at ``anchor_form``) mapped to its
    tiling, warm-started from ``warm``'s equilibrium and ``contacts``' multipliers."""
    form = _uniaxial_form(axis, stretch, free)
    mapped = anchors.transformed(_form_map(form, anchor_form))
    try:
        tiled, result = _solve_from(relaxed, form, np.zeros((2, 2)), options, (warm.result.state, warm.form),
                                    friction=mapped, contacts=contacts)
    except TilingReachError:
        return _Trial(free, form, None, None, mapped, None)
    point = None
    if result.converged:
        slip = mapped.energy_gradient(result.state.node_position)[0]
        point = _FreeStrainPoint(free, (result.energy.internal + slip) / tiled.area,
                                 _green_slope(tiled.model, result, form, _axis_change(1 - axis), tiled.area, mapped))
    return _Trial(free, form, tiled, result, mapped, point)


def _axis_pass(relaxed: RelaxedRepeat, axis: int, stretch: float, anchors: FrictionAnchors, anchor_form: np.ndarray,
               warm: _Trial, contacts: ContactSet, guess: float, probe: float, options: QuasiStaticOptions) -> _Pass:
    """One lagged pass: the free Green strain E⊥ where the potential plus the friction of
    ``anchors`` is least, first tried at ``guess`` and then ``probe`` (> 0) away downhill, then by
    :func:`_next_free_strain`'s secants; a trial that does not converge is approached by halves
    from the nearest equilibrium (:data:`FREE_STRAIN_HALVINGS` at most)."""
    strain = 0.5 * (stretch**2 - 1.0)
    low = max(0.5 * (SMALLEST_FREE_STRETCH**2 - 1.0), -FREE_STRAIN_RANGE * strain)
    trials: list[_Trial] = []
    iterations = 0

    def nearest(free: float) -> _Trial:
        usable = [t for t in trials if t.point is not None]
        return min(usable, key=lambda t: abs(t.free - free)) if usable else warm

    def solve(free: float, depth: int = 0) -> None:
        nonlocal iterations
        start = nearest(free)
        trial = _solve_trial(relaxed, axis, stretch, free, anchors, anchor_form, start, contacts, options)
        iterations += 0 if trial.result is None else trial.result.iterations
        halfway = 0.5 * (start.free + free)
        if trial.point is None and depth < FREE_STRAIN_HALVINGS and abs(halfway - start.free) > FREE_STRAIN_TOLERANCE:
            solve(halfway, depth + 1)
            if nearest(free).free == halfway:
                trial = _solve_trial(relaxed, axis, stretch, free, anchors, anchor_form, nearest(free), contacts,
                                     options)
                iterations += 0 if trial.result is None else trial.result.iterations
        trials.append(trial)

    solve(min(max(guess, low), 0.0))
    verdict = "search"
    for _ in range(FREE_STRAIN_SOLVES):
        points = [t.point for t in trials if t.point is not None]
        if not points:
            verdict = "failed"
            break
        trial, verdict = _next_free_strain(points, low, strain)
        if trial is None:
            break
        if len(points) == 1:
            # The second trial: downhill by the step's expected change of E⊥ (the secants need two;
            # the frictionless search's first guess is for a pull from rest).
            only = points[0]
            trial = min(max(only.free - math.copysign(probe, only.slope), low), 0.0)
            if trial == only.free:
                verdict = "lower end"
                break
        if any(t.free == trial for t in trials):
            verdict = "failed"  # the secants came back to a trial that did not converge
            break
        solve(trial)
    else:
        verdict = "out of solves"
    usable = [t for t in trials if t.point is not None]
    if not usable:
        return _Pass(trials[-1], iterations, "failed")
    if verdict in ("upper end", "plateau", "lower end"):
        chosen = max(usable, key=lambda t: t.free) if verdict == "upper end" else min(usable, key=lambda t: t.free)
    else:
        least = min(t.point.energy for t in usable)
        chosen = min((t for t in usable if t.point.energy <= least + SEARCH_ENERGY_RTOL * abs(least)),
                     key=lambda t: abs(t.point.slope))
    return _Pass(chosen, iterations, verdict)


@dataclass(frozen=True)
class _Step:
    """One frictional load step: its equilibrium, the anchors it was solved with, whether its last
    pass's search converged, whether the anchored normal forces settled, passes and iterations."""

    trial: _Trial
    converged: bool
    settled: bool
    passes: int
    iterations: int

    def accepted(self) -> bool:
        """Its last pass's search converged (so it has a solution) and the normal forces settled."""
        return self.converged and self.settled

    def end(self) -> _Trial:
        """Where the next step starts."""
        return self.trial


@dataclass(frozen=True)
class _PullStep:
    """A load step of a periodic pull (:func:`_frictional_path`) and the strain it pulled to."""

    step: _Step
    strain: float

    def accepted(self) -> bool:
        return self.step.accepted()

    def end(self) -> _Trial:
        """Where the next step starts."""
        return self.step.end()


def _rest(relaxed: RelaxedRepeat, options: QuasiStaticOptions, free=0.0) -> _Trial:
    """The undeformed repeat solved frictionless, at free strains ``free`` (0): every frictional
    path's start. Its convergence is judged with the path's first sample."""
    tiled = tile_repeat(relaxed, np.eye(2), np.zeros((2, 2)))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        rest = QuasiStaticSolver(tiled.model, options).solve(tiled.state, constraints=tiled.constraints)
    return _Trial(free, np.eye(2), tiled, rest, None, None)


def _frictional_step(search: Callable[..., _Pass], start: _Trial, coefficient: float, guess, probe: float) -> _Step:
    """A lagged frictional load step from the equilibrium ``start``: anchored at ``start`` (its
    contacts' normal forces, slip from its positions under its maps), each pass a free-strain
    search ``search(anchors, their form, warm trial, contacts, guess, probe)``
    (:func:`_axis_pass`, :func:`_bias_pass`), re-anchored at its solution until the anchored
    normal force changes by less than :data:`~yarnfit.engine.lagged.LAG_TOLERANCE`. The step is
    converged when its last pass's search is: a pass before it only estimates the normal forces
    the next one anchors, and the last pass minimises with forces that settled (as
    :func:`~yarnfit.engine.lagged.lagged_solve` judges a strip's step by its last pass). Judged
    by every pass, cotton jersey's loading bias sample at 3.98 % was dropped from its fit: its
    path's 2.5 % step had a second pass whose search failed, then a third that found its minimum
    and settled."""
    reference, reference_form = start.result.state.node_position, start.form
    anchors = anchor_contacts(start.tiled.model, reference, start.result.contacts, reference, coefficient)
    anchor_form, warm = reference_form, start
    contacts = start.result.contacts.with_base_penalties()
    iterations = 0
    for passes in range(1, MAX_LAG_PASSES + 1):
        searched = search(anchors, anchor_form, warm, contacts, guess, probe)
        iterations += searched.iterations
        converged = searched.verdict in ("minimum", "upper end", "plateau")
        best = searched.trial
        if best.result is None or not best.result.converged:
            return _Step(best, False, False, passes, iterations)
        back = best.result.contacts.pairs.transformed(_form_map(reference_form, best.form))
        updated = anchor_contacts(best.tiled.model, best.result.state.node_position, best.result.contacts, reference,
                                  coefficient, reference_pairs=back)
        before, after = float(best.anchors.bound.sum()), float(updated.bound.sum())
        change = abs(after - before) / max(after, before) if max(after, before) > 0.0 else 0.0
        if change < LAG_TOLERANCE or coefficient == 0.0:
            return _Step(best, converged, True, passes, iterations)
        anchors, anchor_form, warm, contacts = updated, best.form, best, best.result.contacts
        guess, probe = best.free, max(FREE_STRAIN_PROBE, float(np.max(np.abs(np.subtract(best.free, guess)))))
    return _Step(best, converged, False, MAX_LAG_PASSES, iterations)


def _bias_pass(relaxed: RelaxedRepeat, stretch: float, anchors: FrictionAnchors, anchor_form: np.ndarray,
               warm: _Trial, contacts: ContactSet, guess: np.ndarray, probe: float,
               options: QuasiStaticOptions, angle: float = BIAS_ANGLE) -> _Pass:
    """One lagged pass of a pull at ``angle`` (rad from weft) off the yarn axes: the bias search's
    two free strains (:func:`_search_bias`) from ``guess`` with ``warm``'s equilibrium, minimising
    Ū plus the friction of ``anchors`` (``probe`` unused: the search probes its own Hessian)."""
    search = _search_bias(relaxed, stretch - 1.0, options, angle, start=(guess, warm.result.state, warm.form),
                          friction=(anchors, anchor_form), contacts=contacts)
    trial = _Trial(search.free, search.form, search.tiled, search.result, search.anchors, None)
    return _Pass(trial, search.iterations, "minimum" if search.failure is None else "failed")


def frictional_periodic_pull(relaxed: RelaxedRepeat, axis: int, strains: Sequence[float], coefficient: float,
                             options: QuasiStaticOptions | None = None, strain_step: float = FRICTION_STRAIN_STEP,
                             progress: Callable[[str], None] | None = None) -> list[PeriodicPull]:
    """The infinite fabric of ``relaxed`` pulled along ``axis`` (0 weft, 1 warp) to each of
    ``strains`` (engineering, ascending, > 0) with the other direction free and Coulomb friction
    of ``coefficient`` μ at the yarn contacts (see the module docstring), one
    :class:`~yarnfit.homogenize.PeriodicPull` per strain: force per reference width ``λ dŪ/dE``
    of the potential plus the friction potential (the pull a strip's jaws would feel: the yarns'
    and the friction's), width ``√(1 + 2 E⊥)``; converged when every load step's passes found
    their free strain and the normal forces settled. ``μ = 0`` follows the frictionless
    equilibria along the same path. ``progress(line)`` gets one line per load step. Warns
    :class:`~yarnfit.engine.ConvergenceWarning` for a strain that did not converge."""
    if axis not in (0, 1):
        raise ValueError(f"axis must be 0 (weft) or 1 (warp), got {axis!r}")
    return _frictional_path(relaxed, ("weft", "warp")[axis], strains, coefficient, options, strain_step, progress)


def frictional_periodic_bias_pull(relaxed: RelaxedRepeat, strains: Sequence[float], coefficient: float,
                                  options: QuasiStaticOptions | None = None, strain_step: float = FRICTION_STRAIN_STEP,
                                  progress: Callable[[str], None] | None = None,
                                  other: bool = False) -> list[PeriodicPull]:
    """As :func:`frictional_periodic_pull` on the bias (45° from weft; ``other``: the other bias,
    −45°, direction ``"other bias"``, as :func:`~yarnfit.homogenize.periodic_bias_pull`), each
    pass the bias search with the transverse strain and the pull frame's shear both free
    (:func:`_search_bias`); width ``√det I / λ``."""
    return _frictional_path(relaxed, "other bias" if other else "bias", strains, coefficient, options, strain_step,
                            progress)


def periodic_pulls_along(relaxed: RelaxedRepeat, direction: str, strains: Sequence[float], friction: float = 0.0,
                         options: QuasiStaticOptions | None = None) -> list[PeriodicPull]:
    """The periodic pulls along ``direction`` by name (``"weft"``, ``"warp"``, ``"bias"`` at 45°
    from weft, ``"other bias"`` at −45°: :class:`~yarnfit.homogenize.PeriodicPull`'s directions)
    at each of ``strains`` (engineering, ascending, > 0): with ``friction`` μ > 0 one frictional
    load path from rest (:func:`frictional_periodic_pull`, :func:`frictional_periodic_bias_pull`),
    at 0 the frictionless pulls one by one (:func:`~yarnfit.homogenize.periodic_pull`,
    :func:`~yarnfit.homogenize.periodic_bias_pull`), as the shell's samples are solved."""
    if direction not in PULL_FAMILIES:
        raise ValueError(f"direction must be one of {', '.join(map(repr, PULL_FAMILIES))}, got {direction!r}")
    if friction > 0.0:
        return _frictional_path(relaxed, direction, strains, friction, options, FRICTION_STRAIN_STEP, None)
    strains = _checked_path(strains, friction)  # refuses a NaN or negative coefficient as well
    return [_periodic_pull(relaxed, direction, e, options) for e in strains]


def _checked_path(strains: Sequence[float], coefficient: float) -> list[float]:
    """``strains`` as floats, refused unless positive and ascending, and a friction
    ``coefficient`` refused unless finite and non-negative."""
    strains = [positive_number(e, "strain") for e in strains]
    if not strains or strains != sorted(set(strains)):
        raise ValueError(f"strains must be positive and ascending, got {strains!r}")
    if not (math.isfinite(coefficient) and coefficient >= 0.0):
        raise ValueError(f"friction coefficient must be finite and non-negative, got {coefficient!r}")
    return strains


def _frictional_path(relaxed: RelaxedRepeat, direction: str, strains: Sequence[float], coefficient: float,
                     options: QuasiStaticOptions | None, strain_step: float,
                     progress: Callable[[str], None] | None) -> list[PeriodicPull]:
    """The frictional pull along ``direction`` (``"weft"``, ``"warp"``, ``"bias"`` at 45° from weft,
    ``"other bias"`` at −45°) from rest through ``strains`` (:func:`frictional_periodic_pull`)."""
    strains = _checked_path(strains, coefficient)
    strain_step = positive_number(strain_step, "strain_step")
    options = options or QuasiStaticOptions(max_iterations=MAX_ITERATIONS)
    family = PULL_FAMILIES[direction]
    if family.uniaxial_axis is None:
        angle = family.uniaxial_angle
        pull_direction = np.array([math.cos(angle), math.sin(angle)])

        def search(stretch):
            return lambda *args: _bias_pass(relaxed, stretch, *args, options, angle)
        free = np.zeros(2)
    else:
        axis = family.uniaxial_axis
        pull_direction = np.eye(2)[axis]

        def search(stretch):
            return lambda *args: _axis_pass(relaxed, axis, stretch, *args, options)
        free = 0.0

    state = _rest(relaxed, options, free)
    rest = state.result
    pulls, reached, change, dissipated = [], 0.0, None, 0.0

    def take(start: _Trial, low: float, high: float) -> _PullStep:
        """A load step from ``start`` at the strain ``low`` to ``high``. The free strains change
        per step about as they did in the last one taken; the first step tries the width it starts
        at (where nothing holds the width, it stays) and probes a woven's Poisson ratio."""
        nonlocal change
        step_green = 0.5 * ((1.0 + high) ** 2 - (1.0 + low) ** 2)
        predicted = 0.0 * np.asarray(free) if change is None else change * step_green
        probe = max(FREE_STRAIN_PROBE, float(np.max(np.abs(predicted))), abs(FREE_STRAIN_GUESS * step_green))
        step = _frictional_step(search(1.0 + high), start, coefficient, start.free + predicted, probe)
        if step.accepted():
            change = np.subtract(step.trial.free, start.free) / step_green
        return _PullStep(step, high)

    for strain in strains:
        clock = time.perf_counter()
        if pulls and reached != pulls[-1].strain:
            # An earlier load step failed: the path stops there.
            pulls.append(PeriodicPull(direction, strain, math.nan, math.nan, False, _NO_RESIDUAL, 0, 0.0))
            continue
        steps = load_step_count(reached, strain, strain_step)
        converged, iterations, begin = bool(rest.converged) if not pulls else True, 0, reached
        for j in range(1, steps + 1):
            target = strain if j == steps else begin + (strain - begin) * j / steps
            # A step that does not converge or settle is taken in halves (engine.lagged.in_halves).
            path, tried = in_halves(take, _PullStep.accepted, _PullStep.end, state, reached, target)
            iterations += sum(taken.step.iterations for taken in tried)
            for taken in path:
                step = taken.step
                converged &= step.accepted()
                if step.trial.result is None or not step.trial.result.converged:
                    break
                state, reached = step.trial, taken.strain
                # The step's friction potential at its end is the work its friction dissipated: each
                # anchor beyond its slip length ε pulls μ N along a slip of |u| − ε/3 (a step's slip is
                # a straight line from its start, as the anchors measure it).
                dissipated += state.anchors.energy_gradient(state.result.state.node_position)[0] / state.tiled.area
                if progress is not None:
                    progress(f"{direction} {100 * reached:.2f} %: free strains {np.round(state.free, 5)}, "
                             f"{step.passes} passes, {step.iterations} iterations, "
                             f"{'settled' if step.settled else 'not settled'}")
            if reached != target:
                converged = False
                break
        stretch = 1.0 + strain
        if reached != strain:
            force, width, form, energy = math.nan, math.nan, None, math.nan
            residual = step.trial.result.residual if step.trial.result is not None else _NO_RESIDUAL
        else:
            force = stretch * _green_slope(state.tiled.model, state.result, state.form,
                                           np.outer(pull_direction, pull_direction), state.tiled.area, state.anchors)
            width, residual = math.sqrt(float(np.linalg.det(state.form))) / stretch, state.result.residual
            form, energy = state.form, state.result.energy.internal / state.tiled.area
        if not converged:
            warnings.warn(f"frictional periodic pull along {direction} to {strain:g} did not converge "
                          f"({iterations} iterations)", ConvergenceWarning, stacklevel=3)
        pulls.append(PeriodicPull(direction, strain, force, width, converged, residual, iterations,
                                  time.perf_counter() - clock, form, energy, dissipated))
    return pulls
