"""A quasi-Newton search for the free strains of a sample: the strains nothing prescribes, placed
where Ū is least, each trial a full warm-started solve giving Ū and its envelope-theorem slopes.
The bias pull's two (:mod:`.bias`) and a bend's three membrane strains (:mod:`.bend`) use it."""

from __future__ import annotations

import math
import warnings
from typing import Callable, NamedTuple

import numpy as np

from ..engine import ConvergenceWarning, QuasiStaticResult
from ..engine.friction import FrictionAnchors
from .surface import TiledRepeat


class Trial(NamedTuple):
    """One converged solve of a search: the free strains ``(n,)``, the solve and its tiling, Ū
    (J/m², plus the friction potential for a frictional pass) and Ū's slopes along the free
    strains ``(n,)`` (J/m²), with the friction ``anchors`` it was solved against (or ``None``)."""

    free: np.ndarray
    result: QuasiStaticResult
    tiled: TiledRepeat
    energy: float
    slopes: np.ndarray
    anchors: FrictionAnchors | None = None


def probe_hessian(solve_at: Callable[[np.ndarray], Trial | None], admissible: Callable[[np.ndarray], bool],
                  base: Trial, sizes: np.ndarray) -> tuple[np.ndarray, list[Trial]] | None:
    """The Hessian of Ū in the free strains at ``base`` ``(n, n)``, symmetrised, from one probe
    solve per free strain ``k``, ``sizes[k]`` long towards where its slope points (down Ū), with
    the probes' trials; ``None`` when a probe is not admissible or does not converge."""
    n = len(base.free)
    hessian, probes = np.zeros((n, n)), []
    for k in range(n):
        probe = base.free.copy()
        probe[k] -= math.copysign(sizes[k], base.slopes[k] or 1.0)
        if not admissible(probe) or (point := solve_at(probe)) is None:
            return None
        hessian[:, k] = (point.slopes - base.slopes) / (probe[k] - base.free[k])
        probes.append(point)
    return 0.5 * (hessian + hessian.T), probes


def quasi_newton(solve_at: Callable[[np.ndarray], Trial | None], admissible: Callable[[np.ndarray], bool],
                 current: Trial, hessian: np.ndarray, solves: Callable[[], int], max_solves: int,
                 step_limit: float, step_tolerance: float,
                 balanced: Callable[[Trial, np.ndarray, np.ndarray], bool],
                 settled: Callable[[list[Trial]], bool] | None = None,
                 bound: np.ndarray | None = None, interpolate: bool = False,
                 balanced_ends: bool = False,
                 kink_energy_rtol: float | None = None) -> tuple[Trial, str | None, np.ndarray]:
    """Newton steps on the slopes from ``current`` with ``hessian`` (``(n, n)``, from probes) and
    secant (BFGS) updates, until the step is below ``step_tolerance``: ``(the trial reached, why it
    did not converge or None, the Hessian as updated)``. Each step is at most ``step_limit`` in every free strain and is
    halved until ``solve_at`` (``None`` for a solve that did not converge) gives a trial whose Ū
    or slopes fall; when no step does, the search ends there, found if ``balanced(trial, w, v)``
    says its slopes are spent (``w, v``: the eigenpairs of the Hessian as the steps use it). Found
    too when ``settled`` says so of the trials accepted so far (``current`` first). Not converged
    after ``max_solves`` solves (``solves()`` counts them).

    With ``bound`` ``(n,)`` the free strains stay within ``|free| <= bound`` (a projected Newton):
    a strain at its bound whose slope pushes it further is held there, the step taken in the
    others, and ``balanced`` and ``settled`` see trials whose held slopes are zero.

    With ``interpolate``, a step that raises Ū is not halved but shortened to the least of the
    parabola through Ū and its slope along the step at ``current`` and Ū at the trial (within
    :data:`BACKTRACK_RANGE` of it): a Newton step from a probed Hessian can land where a knit jams,
    Ū many times its start, and halving walked back from there one solve at a time.

    With ``balanced_ends``, ``balanced`` is asked before every step, not only when no step lowers
    Ū: a trial whose slopes are spent is the answer, and the steps that would follow it only move
    about in the contact states' round-off (the stockinette's weft bend at 16.6 /m took three more
    solves after a trial whose slopes were 6e-4 of the start's, and ended 0.15 % above it).
    With ``kink_energy_rtol`` (no ``bound``), a search that would end unconverged ends instead at
    the least Ū it solved when that is a minimum at a kink (:func:`kink_minimum`): two contact
    states meet there, and the search went back and forth between them."""
    kinks = kink_energy_rtol is not None and bound is None
    tried = [current]  # every trial solved, for kink_minimum
    if kinks:
        solve_trial = solve_at

        def solve_at(free: np.ndarray) -> Trial | None:
            point = solve_trial(free)
            if point is not None:
                tried.append(point)
            return point

    def unconverged(current: Trial, failure: str, hessian: np.ndarray) -> tuple[Trial, str | None, np.ndarray]:
        """The search's end where it did not converge: at the kink it found, if asked and there is one."""
        least = kink_minimum(tried, hessian, step_limit, kink_energy_rtol) if kinks else None
        return (current, failure, hessian) if least is None else (least, None, hessian)

    accepted_trials = [_projected(current, bound)]
    while solves() < max_solves:
        held = _held(current, bound)
        moving = ~held
        if not np.any(moving):
            return current, None, hessian  # every strain at a bound, pushing out: the least Ū in the box
        slopes = current.slopes[moving]
        w, v = np.linalg.eigh(hessian[np.ix_(moving, moving)])
        # A curvature that is not positive (a kink, a mechanism), or so small that the step would
        # pass the limit, is replaced by the current slopes over the limit: a step as long as the
        # limit allows. (Not the start's slopes: near a knit's free minimum Ū is far softer than its
        # jammed start, wool jersey's curvature on the bias ~1/60 of the pure stretch's.)
        w = np.maximum(w, max(float(np.abs(slopes).max()), np.finfo(float).tiny) / step_limit)
        if balanced_ends and balanced(current._replace(slopes=slopes), w, v):
            return current, None, hessian
        step = np.zeros(len(current.free))
        step[moving] = -(v / w) @ (v.T @ slopes)
        step *= min(1.0, step_limit / float(np.abs(step).max()))
        if bound is not None:
            step = np.clip(current.free + step, -bound, bound) - current.free
        if float(np.abs(step).max()) <= step_tolerance:
            return current, None, hessian
        accepted = None
        while float(np.abs(step).max()) > step_tolerance and solves() < max_solves:
            trial = current.free + step
            point = solve_at(trial) if admissible(trial) else None
            # Taken if Ū falls or the slopes do: near the minimum warm-started solves land in
            # contact states whose Ū differ by more than the step changes it (the plain weave on
            # the bias at 0.1 %: 3e-7 J/m², 2.5 % of Ū), while the slopes still fall steadily.
            if point is not None and (point.energy < current.energy
                                      or float(np.abs(point.slopes).max()) < float(np.abs(current.slopes).max())):
                accepted = point
                break
            step = _shortened(current, step, point) if interpolate else 0.5 * step
        if accepted is None:
            # No step lowers Ū: its changes are round-off here. Found if the slopes are spent;
            # else the search is stuck.
            if balanced(current._replace(slopes=slopes), w, v):
                return current, None, hessian
            return unconverged(current, "no step of the free strains lowered Ū", hessian)
        moved, change = accepted.free - current.free, accepted.slopes - current.slopes
        if float(moved @ change) > 0.0:  # BFGS keeps the Hessian positive definite
            hs = hessian @ moved
            hessian = hessian - np.outer(hs, hs) / float(moved @ hs) + np.outer(change, change) / float(moved @ change)
        current = accepted
        accepted_trials.append(_projected(current, bound))
        if settled is not None and settled(accepted_trials):
            return current, None, hessian
    return unconverged(current, "the search ran out of solves", hessian)


def kink_minimum(trials: list[Trial], hessian: np.ndarray, step_limit: float, energy_rtol: float) -> Trial | None:
    """The trial of least Ū among ``trials`` if it is a minimum at a kink, else ``None``.

    Near a contact state's end, warm-started solves land on one of two equilibria whose Ū differ
    by more than round-off (the plain weave at 250 g/m² on the bias at 1 %: 0.1093 and 0.1140 J/m²
    at free strains 1.5e-7 apart): the lower one's Ū still falls towards the other, whose slopes
    point back, and the search goes back and forth between them with slopes that never vanish.
    The least Ū is then where the lower state ends, between its last solve and the other's first:
    the trial of least Ū ``L`` is taken when another trial ``R`` lies on a branch above it (Ū more
    than ``energy_rtol`` of Ū(L) higher), with L's slopes falling towards R and R's rising from L,
    and what Ū could still fall is within ``energy_rtol`` of Ū(L) both towards R (L's slope times
    the gap) and across (the decrease a Newton step promises with the slopes' part across the
    gap, the Hessian's curvatures raised as :func:`quasi_newton` raises them)."""
    least = min(trials, key=lambda trial: trial.energy)
    tolerance = energy_rtol * abs(least.energy)
    w, v = np.linalg.eigh(hessian)
    w = np.maximum(w, max(float(np.abs(least.slopes).max()), np.finfo(float).tiny) / step_limit)
    for other in trials:
        gap = other.free - least.free
        if other.energy <= least.energy + tolerance or not float(gap @ gap) > 0.0:
            continue
        towards, back = float(least.slopes @ gap), float(other.slopes @ gap)
        unit = gap / math.sqrt(float(gap @ gap))
        across = least._replace(slopes=least.slopes - float(least.slopes @ unit) * unit)
        if towards < 0.0 < back and -towards <= tolerance and promised_decrease(across, w, v) <= tolerance:
            return least
    return None


# The shortest and longest fraction of a step that raised Ū its parabola may keep (:func:`_shortened`):
# the safeguards of a backtracking line search (Nocedal & Wright, §3.5).
BACKTRACK_RANGE = (0.1, 0.5)


def _shortened(current: Trial, step: np.ndarray, point: Trial | None) -> np.ndarray:
    """The step from ``current`` shortened after its trial ``point`` was refused: to the least of
    the parabola through Ū(0), dŪ/dt(0) = slopes · step and Ū(1) when that lies within
    :data:`BACKTRACK_RANGE`, else to the nearer end of it; halved if the trial did not converge."""
    if point is None:
        return 0.5 * step
    slope = float(current.slopes @ step)
    rise = point.energy - current.energy - slope
    fraction = -slope / (2.0 * rise) if rise > 0.0 and slope < 0.0 else BACKTRACK_RANGE[1]
    return min(max(fraction, BACKTRACK_RANGE[0]), BACKTRACK_RANGE[1]) * step


def _held(trial: Trial, bound: np.ndarray | None) -> np.ndarray:
    """``(n,)`` bool: the free strains at their ``bound`` whose slope pushes them further out."""
    if bound is None:
        return np.zeros(len(trial.free), dtype=bool)
    return (np.abs(trial.free) >= bound) & (trial.free * trial.slopes < 0.0)


def _projected(trial: Trial, bound: np.ndarray | None) -> Trial:
    """``trial`` with the slopes of its held strains (:func:`_held`) zero."""
    held = _held(trial, bound)
    return trial._replace(slopes=np.where(held, 0.0, trial.slopes)) if np.any(held) else trial


def promised_decrease(trial: Trial, w: np.ndarray, v: np.ndarray) -> float:
    """The decrease of Ū a Newton step from ``trial`` still promises, ``½ sᵀ H⁻¹ s`` (J/m²), with
    the Hessian's eigenpairs ``w, v``."""
    return 0.5 * float(trial.slopes @ ((v / w) @ (v.T @ trial.slopes)))


def warn_unconverged(what: str, failure: str | None, result: QuasiStaticResult | None, stacklevel: int) -> None:
    """A :class:`~yarnfit.engine.ConvergenceWarning` that the search for ``what`` (a sample's
    name) did not converge, giving ``failure`` and the residual of its last solve; nothing when
    ``failure`` is ``None``. ``stacklevel`` as :func:`warnings.warn`'s, counted from the caller."""
    if failure is not None:
        warnings.warn(f"{what} did not converge: {failure}" + ("" if result is None else f": {result.residual}"),
                      ConvergenceWarning, stacklevel=stacklevel + 1)
