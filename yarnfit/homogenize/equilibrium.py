"""One tiled sample brought to equilibrium: from the affine start with a continuation when that
fails, or warm-started from a neighbouring equilibrium (a free-strain search's trials), and the
slope of Ū along any in-plane Green strain at an equilibrium (the envelope theorem)."""

from __future__ import annotations

import warnings
from typing import Callable
from dataclasses import replace

import numpy as np

from ..engine import ConvergenceWarning, QuasiStaticOptions, QuasiStaticResult, QuasiStaticSolver, RodModel
from ..engine.contact import TilingReachError
from ..engine.contact_lagrangian import contact_potential
from ..engine.energy import internal_forces
from ..engine.friction import FrictionAnchors
from ..engine.model import aligned_frames
from ..engine.tiling import transform_images
from ..relax import RelaxedRepeat
from .surface import CarriedEquilibrium, TiledRepeat, _form_map, tile_repeat, transfer_fluctuation


# Newton iterations per sample: most take 10–60; the limit only stops a run going nowhere.
MAX_ITERATIONS = 600


# Continuation when a sample cannot be solved in one go from the undeformed repeat: soft
# (fibre-assembly) yarns let a knit's loops roll over each other under a large shear, and Newton
# from the affine start then wanders between contact configurations (polyester jersey at shear
# −0.4: force residual 1e-2 after 4000 iterations). The deformation is then applied in these
# fractions, each solve warm-started from the last one's equilibrium.
CONTINUATION_FRACTIONS = (0.25, 0.5, 0.75, 1.0)
# A continuation step that does not converge is halved (solved from the same equilibrium to
# halfway) at most this many times per sample. A HYLC satin as written (r = 1 mm, 1.7 dtex
# polyester: EI 3e-4 of the solid rod's) at shear 0.2 converges at 0.25, 0.5 and 0.75, while the
# step 0.75 → 1 crawled for 4000 iterations at a torque residual of 5e-5 (damping near 1, steps
# cut to a few percent: the frames twisting through contact configurations); 0.75 → 0.875 → 1
# converged in 155 and 185 iterations.
CONTINUATION_HALVINGS = 4
# Newton iterations per continuation step, as a multiple of the sample's limit (600 → 5400). Its
# steps converge, but slowly where the yarn is very slender in bending: a HYLC basket as written
# (r = 1 mm) in 1.7 dtex polyester is a 2600-tex yarn of 15,000 filaments whose EI is 3e-4 of the
# solid rod's, and its weft stretch at 20 % took 2205 iterations to a force residual of 1e-12 (the
# first 600 ended at 3e-5).
CONTINUATION_ITERATION_FACTOR = 9


def _solve_with_continuation(relaxed: RelaxedRepeat, I, II, options: QuasiStaticOptions,
                             step_options: QuasiStaticOptions | None = None):
    """``(tiled, result, iterations)`` of the sample ``(I, II)``: one solve from the affine start
    and, if it does not converge, a continuation over :data:`CONTINUATION_FRACTIONS` of the
    deformation (``I = 1 + s (I − 1)``, ``II = s II``), each step solved with ``step_options``
    (default: ``options`` with :data:`CONTINUATION_ITERATION_FACTOR` times its iterations) and
    halved when it fails (:data:`CONTINUATION_HALVINGS` times at most). ``iterations`` counts
    every solve's. ``result`` is the full deformation's (converged or, if nothing converged, the
    closer to balance of the direct solve and the continuation's attempts at it), or ``None`` when
    every solve of the full deformation stepped beyond the tiles mapped (:class:`TilingReachError`)."""
    tiled = tile_repeat(relaxed, I, II)
    result, iterations = None, 0
    try:
        with warnings.catch_warnings():
            # Not converging here is not the sample's verdict: the continuation below gives that.
            warnings.simplefilter("ignore", ConvergenceWarning)
            result = QuasiStaticSolver(tiled.model, options).solve(tiled.state, constraints=tiled.constraints)
        iterations = result.iterations
        if result.converged:
            return tiled, result, iterations
    except TilingReachError:
        pass  # a Newton step swept beyond the mapped tiles: smaller steps of deformation may not
    I, II = np.asarray(I, dtype=np.float64), np.asarray(II, dtype=np.float64)
    if step_options is None:
        step_options = replace(options, max_iterations=CONTINUATION_ITERATION_FACTOR * options.max_iterations)
    pending = list(CONTINUATION_FRACTIONS)
    reached, previous, halvings = 0.0, None, 0
    while pending:
        fraction = pending[0]
        step = tile_repeat(relaxed, np.eye(2) + fraction * (I - np.eye(2)), fraction * II)
        if previous is not None:
            transfer_fluctuation(previous[0], previous[1].state, step)
        try:
            with warnings.catch_warnings():
                # A step that fails is halved; the warning below gives the sample's verdict.
                warnings.simplefilter("ignore", ConvergenceWarning)
                solved = QuasiStaticSolver(step.model, step_options).solve(step.state, constraints=step.constraints)
            iterations += solved.iterations
        except TilingReachError:
            solved = None
        if solved is not None and solved.converged:
            reached, previous = fraction, (step, solved)
            pending.pop(0)
            continue
        if fraction == 1.0 and solved is not None and (result is None or solved.residual.force < result.residual.force):
            tiled, result = step, solved
        if halvings == CONTINUATION_HALVINGS:
            break
        halvings += 1
        pending.insert(0, 0.5 * (reached + fraction))
    else:
        return previous[0], previous[1], iterations
    warnings.warn(f"sample did not converge in {iterations} iterations (direct solve and continuation to "
                  f"{reached:g} of the deformation)"
                  + ("" if result is None else f": {result.residual}"), ConvergenceWarning, stacklevel=3)
    return tiled, result, iterations


def _solve_near(relaxed: RelaxedRepeat, I: np.ndarray, II: np.ndarray, options: QuasiStaticOptions,
                near: tuple[TiledRepeat, QuasiStaticResult]) -> tuple[TiledRepeat, QuasiStaticResult | None]:
    """``relaxed`` tiled at ``(I, II)`` (curved or flat) and solved from ``near = (tiling, its
    equilibrium)``, a neighbouring sample's, its fluctuation carried over
    (:func:`~yarnfit.homogenize.surface.transfer_fluctuation`, as the continuation's steps are);
    the result is ``None`` when a step left the tiles mapped. Warnings of a solve that does not
    converge are silenced: the caller judges it."""
    tiled = tile_repeat(relaxed, I, II)
    transfer_fluctuation(near[0], near[1].state, tiled)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            return tiled, QuasiStaticSolver(tiled.model, options).solve(tiled.state, constraints=tiled.constraints)
    except TilingReachError:
        return tiled, None


def _solve_from(relaxed: RelaxedRepeat, form: np.ndarray, II: np.ndarray, options: QuasiStaticOptions,
                previous: tuple | None = None, **solve_args) -> tuple[TiledRepeat, QuasiStaticResult]:
    """``relaxed`` tiled at ``(form, II)`` (a flat sample's) and solved, warnings of a solve that
    does not converge silenced (a search's trial: its caller judges it), from the affine start or,
    with ``previous = (state, its form)``, from that equilibrium mapped by :func:`_form_map` (exact
    for its affine part, and it keeps C_RVE's values, which are linear in the
    positions). Other keywords go to the solve (``friction``, ``contacts``). Raises
    :class:`TilingReachError` when the steps leave the tiles mapped."""
    tiled = tile_repeat(relaxed, form, II)
    state = tiled.state
    if previous is not None:
        prior, prior_form = previous
        matrix = _form_map(form, prior_form)
        state.node_position[:] = prior.node_position @ matrix.T
        state.edge_quaternion[:] = aligned_frames(tiled.model, state.node_position, prior.edge_quaternion)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        result = QuasiStaticSolver(tiled.model, options).solve(state, constraints=tiled.constraints, **solve_args)
    return tiled, result


# Step of a Green strain for the slope of Ū along it (dŪ/dE⊥ across a uniaxial sample, dŪ/dE
# along its pull: central differences along the affine path, see :func:`_green_slope`): nodes
# move ~1e-7 of the repeat (~1e-10 m), inside the contact smoothing band (1.6e-8 m for an 80 µm
# yarn) so the difference stays on one smooth branch, and the energy's round-off (~1e-13
# relative) costs ~1e-6 of the slope. Measured on HYLC's
# stockinette at 5.6 % weft: steps from 5.6e-10 to 5.6e-8 agree to 3e-7 relative, 5.6e-6 is 1e-3 off.
STRAIN_SLOPE_STEP = 1e-7


def _green_slope(model: RodModel, result, form: np.ndarray, change: np.ndarray, area: float,
                 friction: FrictionAnchors | None = None) -> float:
    """dŪ/dh (J/m²) at ``result``, the equilibrium on ``model`` (a flat sample's tiling, first form
    ``form`` ``(2, 2)``), along the Green strain ``E + h change`` (``change`` ``(2, 2)``
    symmetric: ``e_a e_aᵀ`` gives dŪ/dE_aa, the off-diagonal ``½ (e_0 e_1ᵀ + e_1 e_0ᵀ)`` dŪ/d(2 E01)).
    By the envelope theorem it is the derivative of the potential the solve balanced (rods, plus
    the contacts' augmented Lagrangian with the multipliers and penalties it ended with, plus the
    ``friction`` anchors' potential when it was solved with them, their maps at ``form``) along any
    path of configurations that keeps C_RVE; here the affine one, every node and image mapped by
    ``√(I + 2 h change) √I⁻¹`` in the plane (the flat surface's own map is ``√I``: :func:`_form_map`,
    :func:`~yarnfit.engine.tiling.transform_images`,
    :meth:`~yarnfit.engine.contact.ContactPairs.transformed`). Frames stay as they are: they are
    balanced, so turning them changes the potential only to second order."""
    form, change = np.asarray(form, dtype=np.float64), np.asarray(change, dtype=np.float64)

    def potential(step: float) -> float:
        matrix = _form_map(form + 2.0 * step * change, form)
        position = result.state.node_position @ matrix.T
        slip = 0.0 if friction is None else friction.transformed(matrix).energy_gradient(position)[0]
        return (_balanced_potential(transform_images(model, matrix), position, result.state.edge_quaternion,
                                    result.contacts, result.contacts.pairs.transformed(matrix)) + slip)

    return _central_slope(potential, area)


def _surface_green_slope(carried: CarriedEquilibrium, result: QuasiStaticResult, form: np.ndarray,
                         change: np.ndarray) -> float:
    """dŪ/dh (J/m²) at ``result``, the equilibrium ``carried`` holds (its tiling: first form
    ``form``, any second form, flat or curved), along the Green strain ``E + h change``, the second
    form held: :func:`_green_slope`'s envelope-theorem slope along the path that carries the
    equilibrium's corotated fluctuation to the surfaces at ``(form + 2 h change, II)``
    (:class:`~yarnfit.homogenize.surface.CarriedEquilibrium`: C_RVE kept; the frames turned with
    the surface, not re-aligned with their edges, which would move them off the equilibrium by its
    shear: 3e-5 of the plain weave's weft slope at 1 %), the contacts' multipliers and penalties
    as the solve ended. On a flat tiling it is :func:`_green_slope`'s path (measured equal to
    4e-10 relative)."""
    def potential(step: float) -> float:
        model, position, quaternion, pairs = carried.carried(np.asarray(form) + 2.0 * step * np.asarray(change))
        return _balanced_potential(model, position, quaternion, result.contacts, pairs)

    return _central_slope(potential, carried.tiled.area)


def _balanced_potential(model: RodModel, position: np.ndarray, quaternion: np.ndarray, contacts, pairs) -> float:
    """The potential a solve balanced (J), at moved ``position`` ``(N, 3)`` and frames: the rods'
    energy plus the contacts' augmented Lagrangian with ``contacts``' multipliers and penalties on
    ``pairs`` (its pairs, moved with the nodes)."""
    rods = sum(internal_forces(model, position, quaternion).terms)
    return rods + contact_potential(model, position, replace(contacts, pairs=pairs))


def _central_slope(potential: Callable[[float], float], area: float) -> float:
    """``(potential(δ) − potential(−δ)) / (2 δ area)`` with δ = :data:`STRAIN_SLOPE_STEP`: the
    slope (J/m²) of a potential along a strain path parametrised by ``h``."""
    return (potential(STRAIN_SLOPE_STEP) - potential(-STRAIN_SLOPE_STEP)) / (2.0 * STRAIN_SLOPE_STEP * area)


def _axis_change(axis: int) -> np.ndarray:
    """``e_a e_aᵀ``: the Green strain direction of E_aa (:func:`_green_slope`)."""
    change = np.zeros((2, 2))
    change[axis, axis] = 1.0
    return change
