"""Frictional load steps: the quasi-static solve repeated with friction anchors re-anchored at
each solution until the normal forces that bound the friction settle (IPC's lagged iterations,
:mod:`yarnfit.engine.friction`). Above both the solver and the anchors: it drives the one with
the other."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, TypeVar

import numpy as np

from .contact_lagrangian import ContactSet
from .friction import FrictionAnchors, anchor_contacts
from .quasistatic import QuasiStaticResult, QuasiStaticSolver
from .state import RodState

__all__ = ["FRICTION_STRAIN_STEP", "LAG_TOLERANCE", "MAX_LAG_PASSES", "STEP_HALVINGS", "LaggedSolve", "in_halves",
           "lagged_solve", "load_step_count"]


@dataclass(frozen=True)
class LaggedSolve:
    """Outcome of :func:`lagged_solve`: the last solve's result and the anchors it was solved
    with, whether the normal forces settled, the number of lagged passes and Newton iterations
    over all of them, and the relative change of the total anchored normal force between the
    last two passes."""

    result: QuasiStaticResult
    anchors: FrictionAnchors
    settled: bool
    passes: int
    iterations: int
    force_change: float


# Lagged passes stop when the anchored normal forces' total changes by less than this fraction
# between passes (IPC iterates its lagging to a tolerance the same way): the friction bound μ N
# is then that close to the step's own normal forces. Friction raises the normal forces it is
# bounded by (it holds yarn tension that presses the crossings), so the passes climb: the
# cotton twill's warp strip from rest to 2 % anchored 1.5, 3.2, 4.6, 5.5, 5.9, 6.07, 6.08 N over
# its first seven passes, its pull 434 → 815 N/m. It settled in 7 / 4 / 8 passes at 2 / 5 / 10 %;
# wool jersey's 4 × 3 warp strip at 5 % still moved 1.2 % at the tenth (each pass closing ~35 %
# of the remaining gap), and the passes after the first few take tens of Newton iterations each.
# Letting the bounds follow the contact multipliers within a solve (at each update) was tried and
# not kept: the multipliers are the normal forces only to the contact tolerance, so such a bound
# never matched its solution's forces (0.76 % apart on the dragged rod of tests/test_friction.py),
# and on that wool strip it took 326 / 2210 Newton iterations at 2 / 5 % against 241 / 503.
# Largest strain increment of a frictional load step: a pull with friction (a cut strip,
# :func:`yarnfit.validate.swatch.stretch_swatch`; the periodic repeat,
# :func:`yarnfit.homogenize.frictional_periodic_pull`) reaches each reported strain in equal steps
# no larger than this. Lagged friction (IPC) charges each contact the net
# slip of its whole step against normal forces frozen per pass, so a large step slides contacts
# that the path would have held, and the frictional strip comes out soft and step-dependent: the
# cotton twill's warp strip (1819 nodes) at 2 % pulls at 815 / 821 / 1235 / 1227 N/m reached in
# 1 / 2 / 4 / 8 steps, and 0.5 % steps agree with 0.25 % ones to 0.7 % up to 3 % (2177 against
# 2167 N/m) at ~8 s a step (session 33). Beyond 3 % that strip slips in events (its pull falls
# 2177 → 1575 N/m in one 0.5 % step at 3.5 %, 2075 → 1159 at 6 %; 9–12 lagged passes, ~65 s each
# such step), whose timing depends on the path: at 10 % it pulls 1796 N/m in steps of 0.5 % and
# 2142 in steps of 0.25 % (645 in one step from 5 %), so a strip that small has no sharper figure
# there. A frictionless pull has no path and takes each strain in one step.
FRICTION_STRAIN_STEP = 0.005
# Round-off allowance in counting a pull's load steps: 0.05 − 0.02 is 0.030000000000000002, which
# must be six steps of 0.5 %, not seven.
STEP_COUNT_SLACK = 1e-9
LAG_TOLERANCE = 1e-2
MAX_LAG_PASSES = 20


def lagged_solve(solver: QuasiStaticSolver, guess: RodState, reference: np.ndarray, coefficient: float, *,
                 anchors_from: tuple[np.ndarray, ContactSet] | None = None, slip_length: float | None = None,
                 tolerance: float = LAG_TOLERANCE, max_passes: int = MAX_LAG_PASSES, **solve_args) -> LaggedSolve:
    """A frictional load step: solve from ``guess`` (a :class:`~yarnfit.engine.RodState`) with
    friction anchored at ``reference`` (the step's start, ``(N, 3)`` m), re-anchor at the solution
    (normal forces, tangent planes and contact points there, slip still from ``reference``) and
    solve again from it, until the anchored normal force changes by less than ``tolerance`` (or
    ``max_passes``). ``anchors_from`` ``(position, contacts)``: where the first pass takes its
    normal forces (the step's start, solved; default: a frictionless first pass). ``solver`` a
    :class:`~yarnfit.engine.QuasiStaticSolver`; other keywords go to its ``solve``.

    Each pass starts from the last one's contact multipliers and penalties (``solve(contacts=...)``),
    the first from the multipliers of ``anchors_from`` at base penalties (a new load step,
    :meth:`~yarnfit.engine.contact_lagrangian.ContactSet.with_base_penalties`): a pass starts at the last one's
    solution, where they nearly balance, and from zero every pass spent its first multiplier
    updates pushing the residual back up (design notes §5, "Lagged friction")."""
    model = solver.model
    if anchors_from is None:
        result = solver.solve(guess, **solve_args)
        anchors_from = (result.state.node_position, result.contacts)
        guess, iterations, passes = result.state, result.iterations, 1
    else:
        iterations, passes = 0, 0
    anchors = anchor_contacts(model, anchors_from[0], anchors_from[1], reference, coefficient, slip_length)
    # The step's normal forces are those the step's start was solved with; its first pass starts
    # from their multipliers but from base penalties (ContactSet.with_base_penalties).
    contacts = anchors_from[1].with_base_penalties()
    while True:
        result = solver.solve(guess, friction=anchors, contacts=contacts, **solve_args)
        iterations += result.iterations
        passes += 1
        updated = anchor_contacts(model, result.state.node_position, result.contacts, reference, coefficient,
                                  slip_length)
        before, after = float(anchors.bound.sum()), float(updated.bound.sum())
        change = abs(after - before) / max(after, before) if max(after, before) > 0.0 else 0.0
        if change < tolerance or passes >= max_passes or coefficient == 0.0:
            return LaggedSolve(result, anchors, change < tolerance, passes, iterations, change)
        anchors, guess, contacts = updated, result.state, result.contacts


# A frictional load step that does not converge or settle is taken again in two halves, each
# halved again, this many times at most (down to a quarter step: 0.125 % of FRICTION_STRAIN_STEP's
# 0.5 %). A step charges its whole slip against normal forces taken from its end, and a long step's
# passes can cycle between two sets of them (polyester jersey's biaxial loading path at 31.5 %:
# anchored totals 4.756 and 4.866 N for twenty passes) or climb without settling (wool jersey's weft
# compression at 1 %); shorter steps settle both (docs/design.md §5, "Passes that cycle"). A
# quarter step that still fails is a jam (cotton jersey's compression beyond 7 %: no step
# converges there even at 0.1 %).
STEP_HALVINGS = 2

Step = TypeVar("Step")


def in_halves(take: Callable[[object, float, float], Step], accepted: Callable[[Step], bool],
              end: Callable[[Step], object], start: object, low: float, high: float,
              halvings: int = STEP_HALVINGS) -> tuple[list[Step], list[Step]]:
    """A load step from ``start`` (the path's state at the load ``low``) to ``high``:
    ``take(start, low, high)``, and when that step is not ``accepted``, two halves instead, each
    taken the same way with one halving fewer (the second from ``end(first)``, the state the first
    reached). Returns ``(path, tried)``: the steps that carry the path towards ``high``, each from
    the last one's end (the full step alone when its first half failed too; ending on the failed
    one when a later half failed), and every step taken, in order (their work is all spent)."""
    step = take(start, low, high)
    if accepted(step) or halvings <= 0:
        return [step], [step]
    middle = 0.5 * (low + high)
    first, tried = in_halves(take, accepted, end, start, low, middle, halvings - 1)
    tried = [step] + tried
    if not accepted(first[-1]):
        return [step], tried
    second, more = in_halves(take, accepted, end, end(first[-1]), middle, high, halvings - 1)
    return first + second, tried + more


def load_step_count(start: float, end: float, largest: float) -> int:
    """Equal load steps from the strain ``start`` to ``end`` (> ``start``) no larger than
    ``largest`` (:data:`FRICTION_STRAIN_STEP`): at least one."""
    return max(1, math.ceil((end - start) / largest - STEP_COUNT_SLACK))
