"""Homogenization (paper §4.5, phase 2): the relaxed repeat tiled over a deformed mid-surface.

A sample is a pair of constant fundamental forms ``(I, II)`` (``I`` 2×2 SPD, ``II`` 2×2 symmetric,
1/m; the rest surface is flat with ``I = Id``). Every node of the relaxed repeat has reference
coordinates ``X`` in the fabric plane (measured from the repeat's centre) and a height ``h`` above
its mid-plane; it is placed at ``x = φ(X) + h n(X) + ũ`` on a mid-surface ``φ`` whose fundamental
forms at ``X = 0`` are ``(I, II)``, with ``R(X) = [∂φ polar rotation | n]`` the surface frame:

- ``φ(X) = β(S X)``, ``S = I^{1/2}`` (symmetric: a pure membrane sample turns nothing), and ``β``
  the bent plane with second fundamental form ``II' = S⁻¹ II S⁻¹``: a **circular cylinder** when
  ``II'`` is singular (single, bias and any other developable bend: exact, its metric is ``I``
  everywhere), otherwise a quadric ``(Y, ½ Yᵀ II' Y)`` with cubic corrections in the plane. A
  saddle's Gauss curvature K cannot live on a flat metric: the corrections cancel the quadric's
  own metric strain (``κ² Y²``) and leave the Gauss defect ``K Y² / 4`` per axis, which the saddle
  curvatures keep small (see :func:`sample_design`).
- Periodicity (``C_RVE_Γ``): the image of node i in tile T is where its co-rotated fluctuation
  ``Rᵀ ũ`` is the same at ``X_i + T``: ``Q x + c`` with ``Q = R(X_i + T) R(X_i)ᵀ``. These per-node
  rigid maps (:class:`~yarnfit.engine.tiling.CurvedTiling`) carry ghost-edge ends, frames across
  tile borders (so the twist across a border is the twist of a real joint: the paper's matching
  end twist, and no net twist can build up from tile to tile) and contacts with every image.
- ``C_RVE``: per yarn, ``Σ_j R_jᵀ ũ_j = 0`` — linear in the positions since ``R_j`` is fixed.

The quasi-static solver then minimises the yarn energy; ``Ū = U / (p_x p_y)`` (J/m² of reference
area) with its residual is the sample's result. Samples are independent and run in parallel.
"""

from __future__ import annotations

import math
import os
import time
import warnings
from dataclasses import dataclass, replace
from typing import Callable, Sequence

import numpy as np

from .checks import positive_number
from .engine import (ConvergenceWarning, LinearConstraints, QuasiStaticOptions, QuasiStaticResult, QuasiStaticSolver,
                     Residual, RodModel, RodState)
from .engine.contact import TilingReachError, image_range
from .engine.contact_lagrangian import contact_potential
from .engine.energy import internal_forces
from .engine.model import aligned_frames
from .engine.rotations import rotate_frames
from .engine.tiling import CurvedTiling, retile, transform_images
from .relax import RelaxedRepeat, yarn_centroid_constraints
from .samples import UNIAXIAL_FAMILIES, Family, SampleRanges, SampleResult, SampleSpec, stretch_share
from .shell import as_first_fundamental_form, as_second_fundamental_form
from .tasks import Backend, LocalPool, Task, run_tasks

# A bend whose |det II'| is below this fraction of ‖II'‖² is a cylinder (developable); the
# sample design's bends are exactly singular or far from it.
DEVELOPABLE_TOLERANCE = 1e-12
# Newton iterations per sample: most take 10–60; the limit only stops a run going nowhere.
MAX_ITERATIONS = 600
# Tiles of maps beyond those the rest configuration's contacts reach: contact queries during line
# searches sweep further (the step's length is added to the reach).
EXTRA_TILES = 2


def _spd_sqrt(matrix: np.ndarray) -> np.ndarray:
    """The symmetric square root of a symmetric positive-definite ``(2, 2)`` matrix."""
    w, v = np.linalg.eigh(matrix)
    return (v * np.sqrt(w)) @ v.T


def _form_map(target: np.ndarray, source: np.ndarray) -> np.ndarray:
    """``(3, 3)``: the linear map taking a flat tiling at first form ``source`` to one at
    ``target`` (both ``(2, 2)``), ``√target √source⁻¹`` in the plane. Axis-aligned forms map by
    the exact stretch ratio per axis (an unchanged axis by 1.0): through the general square roots,
    round-off alone sent cotton jersey's 10 % warp pull to another of its equilibria."""
    target, source = np.asarray(target, dtype=np.float64), np.asarray(source, dtype=np.float64)
    matrix = np.eye(3)
    if target[0, 1] == 0.0 and source[0, 1] == 0.0:
        matrix[[0, 1], [0, 1]] = np.sqrt(np.diag(target) / np.diag(source))
    else:
        matrix[:2, :2] = _spd_sqrt(target) @ np.linalg.inv(_spd_sqrt(source))
    return matrix


@dataclass(frozen=True, eq=False)
class SurfaceMap:
    """The deformed mid-surface of one sample: ``φ`` with ``I`` and ``II`` at ``X = 0``."""

    I: np.ndarray
    II: np.ndarray

    def __post_init__(self) -> None:
        I = as_first_fundamental_form(self.I)
        II = as_second_fundamental_form(self.II)
        if I.shape != (2, 2) or II.shape != (2, 2):
            raise ValueError(f"a surface map takes one (2, 2) I and II, got {I.shape} and {II.shape}")
        object.__setattr__(self, "I", 0.5 * (I + I.T))
        object.__setattr__(self, "II", 0.5 * (II + II.T))

    @property
    def stretch(self) -> np.ndarray:
        """``S = I^{1/2}`` (2×2 SPD)."""
        return _spd_sqrt(self.I)

    @property
    def bend(self) -> np.ndarray:
        """``II' = S⁻¹ II S⁻¹``: the bend in the stretched plane's coordinates (1/m)."""
        inv = np.linalg.inv(self.stretch)
        return inv @ self.II @ inv

    def evaluate(self, X: np.ndarray, height: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Points ``φ(X) + h n(X)`` ``(n, 3)`` (m), normals ``(n, 3)`` and surface frames
        ``R (n, 3, 3)`` (columns: the polar rotation of ∂φ, then n) at reference points
        ``X (n, 2)`` (m)."""
        X = np.asarray(X, dtype=np.float64).reshape(-1, 2)
        S = self.stretch
        Y = X @ S  # S symmetric: row-wise S X
        point, tangent = _bent_plane(self.bend, Y)
        gradient = tangent @ S  # ∂φ/∂X = ∂β/∂Y S, (n, 3, 2)
        frame = _surface_frame(gradient)
        normal = frame[:, :, 2]
        if height is not None:
            point = point + np.asarray(height, dtype=np.float64).reshape(-1, 1) * normal
        return point, normal, frame


def _bent_plane(bend: np.ndarray, Y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points ``(n, 3)`` and tangents ``∂β/∂Y (n, 3, 2)`` of the plane bent to second fundamental
    form ``bend`` at the origin: a circular cylinder if ``bend`` is singular, else a quadric."""
    n = Y.shape[0]
    point = np.zeros((n, 3))
    tangent = np.zeros((n, 3, 2))
    scale = float(np.abs(bend).max())
    if scale == 0.0:
        point[:, :2] = Y
        tangent[:, 0, 0] = tangent[:, 1, 1] = 1.0
        return point, tangent
    w, v = np.linalg.eigh(bend)
    if abs(w[0] * w[1]) <= DEVELOPABLE_TOLERANCE * scale**2:
        # Cylinder: curvature κ along u, straight along v = u turned by +90° (so u × v = e_z).
        k = int(np.argmax(np.abs(w)))
        kappa, u = float(w[k]), v[:, k]
        across = np.array([-u[1], u[0]])
        s, t = Y @ u, Y @ across
        u3, across3 = np.array([u[0], u[1], 0.0]), np.array([across[0], across[1], 0.0])
        angle = kappa * s
        point = (np.outer(t, across3) + np.outer(np.sin(angle) / kappa, u3)
                 + np.outer(2.0 * np.sin(0.5 * angle) ** 2 / kappa, [0.0, 0.0, 1.0]))
        along = np.outer(np.cos(angle), u3) + np.outer(np.sin(angle), [0.0, 0.0, 1.0])  # ∂β/∂s
        tangent = along[:, :, None] * u[None, None, :] + across3[None, :, None] * across[None, None, :]
        return point, tangent
    # Non-developable (saddle or dome): no surface carries this bend on a flat metric (Gauss). In
    # principal coordinates Z, the quadric (Z, ½ Σ κ_i Z_i²) strains the metric by κ_i² Z_i² along
    # each axis; the cubic terms below cancel that to second order and leave only the Gauss
    # defect, split evenly: g = diag(1 − K Z2²/2, 1 − K Z1²/2) + O(Z⁴), K = κ1 κ2.
    z = Y @ v
    k1, k2 = w
    gauss = k1 * k2
    z1, z2 = z[:, 0], z[:, 1]
    local = np.column_stack([
        z1 - k1**2 * z1**3 / 6.0 - 0.25 * gauss * z1 * z2**2,
        z2 - k2**2 * z2**3 / 6.0 - 0.25 * gauss * z1**2 * z2,
    ])
    point[:, :2] = local @ v.T
    point[:, 2] = 0.5 * (k1 * z1**2 + k2 * z2**2)
    d_local = np.empty((n, 2, 2))  # ∂(local)/∂Z
    d_local[:, 0, 0] = 1.0 - 0.5 * k1**2 * z1**2 - 0.25 * gauss * z2**2
    d_local[:, 0, 1] = d_local[:, 1, 0] = -0.5 * gauss * z1 * z2
    d_local[:, 1, 1] = 1.0 - 0.5 * k2**2 * z2**2 - 0.25 * gauss * z1**2
    tangent[:, :2, :] = v @ d_local @ v.T
    tangent[:, 2, :] = np.column_stack([k1 * z1, k2 * z2]) @ v.T
    return point, tangent


def _surface_frame(gradient: np.ndarray) -> np.ndarray:
    """``(n, 3, 3)`` frames: the rotation of the polar decomposition ``∂φ = R₂ U`` (two columns)
    and the unit normal ``r₁ × r₂``.

    ``R₂ = G C^(-1/2)`` with ``C = GᵀG`` (2×2 SPD for a surface map of full rank), in closed form:
    ``√C = (C + s Id)/t`` with ``s = √det C``, ``t = √(tr C + 2 s)`` (Cayley–Hamilton), inverted
    as a 2×2. It equals the SVD's ``U Vᵀ`` to round-off and costs a tenth of numpy's batched SVD
    over the tens of thousands of image points a curved tiling evaluates."""
    C = np.einsum("nki,nkj->nij", gradient, gradient)
    s = np.sqrt(C[:, 0, 0] * C[:, 1, 1] - C[:, 0, 1] * C[:, 1, 0])
    t = np.sqrt(C[:, 0, 0] + C[:, 1, 1] + 2.0 * s)
    root = C.copy()
    root[:, 0, 0] += s
    root[:, 1, 1] += s
    root /= t[:, None, None]
    det = root[:, 0, 0] * root[:, 1, 1] - root[:, 0, 1] * root[:, 1, 0]
    inverse = np.empty_like(root)
    inverse[:, 0, 0], inverse[:, 1, 1] = root[:, 1, 1] / det, root[:, 0, 0] / det
    inverse[:, 0, 1], inverse[:, 1, 0] = -root[:, 0, 1] / det, -root[:, 1, 0] / det
    r2 = gradient @ inverse
    normal = np.cross(r2[:, :, 0], r2[:, :, 1])
    return np.concatenate([r2, normal[:, :, None]], axis=2)


# -- the repeat on the surface ---------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class TiledRepeat:
    """A relaxed repeat placed on a sample's mid-surface, ready to solve.

    Attributes:
        surface: the mid-surface.
        model: the relaxed rest model on the curved tiling.
        state: the initial configuration (``ũ = 0``, frames turned with the surface).
        constraints: ``C_RVE`` (3 rows per yarn).
        reference: ``(N, 2)`` m, nodes' reference coordinates from the repeat's centre.
        height: ``(N,)`` m, nodes' heights above the mid-plane.
        area: ``p_x p_y`` (m²).
    """

    surface: SurfaceMap
    model: RodModel
    state: RodState
    constraints: LinearConstraints
    reference: np.ndarray
    height: np.ndarray
    area: float


def tile_repeat(relaxed: RelaxedRepeat, I, II) -> TiledRepeat:
    """Place ``relaxed`` on the mid-surface of ``(I, II)`` (see the module docstring)."""
    surface = SurfaceMap(np.asarray(I, dtype=np.float64), np.asarray(II, dtype=np.float64))
    flat = relaxed.model
    px, py = (float(v) for v in relaxed.repeat_size)
    rest = flat.node_rest_position
    reference = rest[:, :2] - np.array([0.5 * px, 0.5 * py])
    height = rest[:, 2] - rest[:, 2].mean()
    position, _, frame = surface.evaluate(reference, height)
    tiling = _curved_tiling(surface, flat, reference, height, position, frame, (px, py))
    lattice = surface.evaluate(np.array([[px, 0.0], [0.0, py], [0.0, 0.0]]))[0]
    model = retile(flat, tiling, lattice[:2] - lattice[2])
    quaternion = _turned_frames(model, relaxed.state.edge_quaternion, reference, (px, py), surface)
    state = RodState.from_model(model)
    state.node_position[:] = position
    state.edge_quaternion[:] = aligned_frames(model, position, quaternion)
    # C_RVE: per yarn and axis k, Σ_j (R_jᵀ x_j)_k keeps its initial value.
    return TiledRepeat(surface, model, state, yarn_centroid_constraints(model, frame), reference, height, px * py)


def _curved_tiling(surface, flat, reference, height, position, frame, repeat) -> CurvedTiling:
    """Per-node maps onto every tile the contacts can reach (with EXTRA_TILES to spare)."""
    # As find_pairs reaches: two radii, a margin of about one, and an edge.
    reach = 3.0 * float(flat.edge_radius.max()) + float(flat.edge_rest_length.max())
    # A compressed direction brings images closer: the same reach spans more tiles.
    smallest_stretch = math.sqrt(float(np.linalg.eigvalsh(surface.I).min()))
    needed = int(math.ceil(image_range(flat, flat.node_rest_position, reach).max() / smallest_stretch))
    extent = needed + EXTRA_TILES
    offsets = np.arange(-extent, extent + 1)
    images = np.array([(0, 0)] + [(i, j) for i in offsets for j in offsets if (i, j) != (0, 0)], dtype=np.int64)
    n, k = len(reference), len(images)
    shifted = (reference[:, None, :] + (images * np.asarray(repeat))[None, :, :]).reshape(-1, 2)
    image_position, _, image_frame = surface.evaluate(shifted, np.repeat(height, k))
    image_position = image_position.reshape(n, k, 3)
    image_frame = image_frame.reshape(n, k, 3, 3)
    # optimize=True: numpy's plain einsum loops over the N K tiny products ~20x slower.
    rotation = np.einsum("nkij,nlj->nkil", image_frame, frame, optimize=True)  # R(X + T) R(X)ᵀ
    translation = image_position - np.einsum("nkij,nj->nki", rotation, position, optimize=True)
    rotation[:, 0], translation[:, 0] = np.eye(3), 0.0  # the home tile exactly
    return CurvedTiling(images, np.ascontiguousarray(rotation), np.ascontiguousarray(translation))


def _turned_frames(model: RodModel, quaternion: np.ndarray, reference: np.ndarray, repeat, surface) -> np.ndarray:
    """Relaxed frames turned by the surface frame at each edge's reference midpoint."""
    start = reference[model.edge_nodes[:, 0]]
    end = reference[model.edge_nodes[:, 1]] + model.edge_tile * np.asarray(repeat)
    frame = surface.evaluate(0.5 * (start + end))[2]
    return rotate_frames(frame, quaternion)


# -- one sample -----------------------------------------------------------------------------------


def solve_sample(relaxed: RelaxedRepeat, spec: SampleSpec, options: QuasiStaticOptions | None = None) -> SampleResult:
    """Tile ``relaxed`` on the sample's surface and minimise the yarn energy under ``C_RVE``.

    A uniaxial-tension sample also minimises over its free strains: the transverse stretch μ along
    a yarn axis (:func:`_solve_uniaxial`), and on the bias the transverse strain and the pull
    frame's shear (:func:`_solve_bias`); its result's spec carries the form found."""
    start = time.perf_counter()
    options = options or QuasiStaticOptions(max_iterations=MAX_ITERATIONS)
    if spec.family.uniaxial_axis is not None:
        return _solve_uniaxial(relaxed, spec, options, start)
    if spec.family.uniaxial_angle is not None:
        return _solve_bias(relaxed, spec, options, start)
    tiled, result, iterations = _solve_with_continuation(relaxed, spec.I, spec.II, options)
    if result is None:
        # No solve of this deformation stayed within the mapped tiles: nothing to report but that.
        return SampleResult(spec=spec, energy_density=math.nan, converged=False,
                            residual=Residual(math.nan, math.nan, math.nan, math.nan), iterations=iterations,
                            seconds=time.perf_counter() - start, position=tiled.state.node_position)
    return SampleResult(
        spec=spec,
        energy_density=result.energy.internal / tiled.area,
        converged=result.converged,
        residual=result.residual,
        iterations=iterations,
        seconds=time.perf_counter() - start,
        position=result.state.node_position,
        stretch_share=stretch_share(result.energy),
    )


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


def transfer_fluctuation(source: TiledRepeat, state: RodState, target: TiledRepeat) -> None:
    """Start ``target`` from ``state``, an equilibrium of ``source``: each node keeps its
    fluctuation ``ũ = x − φ(X) − h n`` in its surface frame (``ũ_target = R_t R_sᵀ ũ_source``, the
    corotated fluctuation C_RVE constrains), each frame turns with its first node's surface frame
    and is then aligned with its edge. Writes ``target.state``."""
    base_source, _, frame_source = source.surface.evaluate(source.reference, source.height)
    base_target, _, frame_target = target.surface.evaluate(target.reference, target.height)
    turn = np.einsum("nij,nkj->nik", frame_target, frame_source)
    position = base_target + np.einsum("nij,nj->ni", turn, state.node_position - base_source)
    quaternion = rotate_frames(turn[target.model.edge_nodes[:, 0]], state.edge_quaternion)
    target.state.node_position[:] = position
    target.state.edge_quaternion[:] = aligned_frames(target.model, position, quaternion)


# -- uniaxial tension (weft or warp, the other direction free) -----------------------------------

# Tolerance on the free Green strain E⊥ = (μ² − 1)/2: Ū is flat at its minimum, so an error δ
# costs about ½ k δ² with k the pure transverse stiffness (~1e5 J/m² for the presets): 1e-4 leaves
# ~5e-4 J/m², a few percent of the smallest uniaxial Ū measured (jersey at 1 %: 3e-2 J/m²) and far
# less at the larger strains the fit weighs most.
FREE_STRAIN_TOLERANCE = 1e-4
# Search interval of E⊥ in units of the prescribed strain E: knits contract by up to ~1.5 times
# their stretch at small strain (measured on cotton jersey); 3 leaves room; μ stays ≥ 0.5.
FREE_STRAIN_RANGE = 3.0
SMALLEST_FREE_STRETCH = 0.5
# First trial of E⊥ / E when the pure stretch's slope gives no curvature yet: a woven's Poisson
# ratio (0.2–0.3); the secants take it from there.
FREE_STRAIN_GUESS = -0.3
# Solves per uniaxial sample at most; the secants on the slope typically need 2–6. With
# fibre-assembly yarns a jersey's minimum can sit at a kink (its wales jam) and warm starts land on
# a neighbouring branch of equilibria, which a search approaches at bisection's pace: wool jersey,
# course-wise at 15 %, took 27 solves of the parabolas this search replaced.
FREE_STRAIN_SOLVES = 40
# A trial E⊥ whose solve fails from the nearest equilibrium is approached by solving halfway first,
# at most this many times nested (each halving is one more point the search can use).
FREE_STRAIN_HALVINGS = 3
# Inside a bracket the search stops when the decrease of Ū the least slope still promises,
# s² / (2 k), is below this relative to Ū *and* that slope is below FREE_SLOPE_RTOL of the pure
# stretch's (or the root is within FREE_STRAIN_TOLERANCE). Ū alone is too flat about its minimum
# to place E⊥ (satin at 5 %: ½ k δ² ≈ 1e-3 Ū for δ = 0.009, ±10 % on the Poisson ratio), and the
# slope alone is fooled by a jersey's slack side (slope 0.2 % of the pure stretch's, Ū 8 % above
# the least). Points whose Ū lies within this of the least found count as one equilibrium, and
# the result is the one of least slope among them: warm-started solves of a knit land in nearby
# equilibria whose Ū differ by ~1e-4, while a point further above is on another branch
# (polyester jersey, wale-wise at 5 %: slope 0.03 J/m² at a Ū 2.2e-3 above the least found).
SEARCH_ENERGY_RTOL = 1e-3
# The transverse stress left at the result, as a fraction of the pure stretch's (the slope at
# E⊥ = 0): where the slope is near linear this puts E⊥ within 1 % of its root, the Poisson ratio
# to ~1 %.
FREE_SLOPE_RTOL = 0.01
# A slope this small against Ū over the whole search interval means Ū does not depend on E⊥
# (nothing resists the transverse direction, as between straight parallel yarns): round-off of
# the energy sum (1e-16 × the number of terms) over the slope's step, with a wide margin.
FLAT_ENERGY_RTOL = 1e-6
# Shortest step of an unbracketed search: ten tolerances, past a minimum its secant step has
# all but reached, so that the slope changes sign there.
FREE_STRAIN_PROBE = 10.0 * FREE_STRAIN_TOLERANCE
# A minimum at the interval's lower end counts as a plateau if Ū would fall by less than this
# (relative) towards its neighbour: the energy has stopped changing with E⊥ to the accuracy the
# fit can use.
PLATEAU_RTOL = 1e-3
# Step of a Green strain for the slope of Ū along it (dŪ/dE⊥ across a uniaxial sample, dŪ/dE
# along its pull: central differences along the affine path, see :func:`_green_slope`): nodes
# move ~1e-7 of the repeat (~1e-10 m), inside the contact smoothing band (1.6e-8 m for an 80 µm
# yarn) so the difference stays on one smooth branch, and the energy's round-off (~1e-13
# relative) costs ~1e-6 of the slope. Measured on HYLC's
# stockinette at 5.6 % weft: steps from 5.6e-10 to 5.6e-8 agree to 3e-7 relative, 5.6e-6 is 1e-3 off.
STRAIN_SLOPE_STEP = 1e-7


@dataclass(frozen=True)
class _FreeStrainPoint:
    """One converged solve of a uniaxial search: E⊥, Ū (J/m²) and dŪ/dE⊥ (J/m²)."""

    free: float
    energy: float
    slope: float


def _green_slope(model: RodModel, result, form: np.ndarray, change: np.ndarray, area: float) -> float:
    """dŪ/dh (J/m²) at ``result``, the equilibrium on ``model`` (a flat sample's tiling, first form
    ``form`` ``(2, 2)``), along the Green strain ``E + h change`` (``change`` ``(2, 2)``
    symmetric: ``e_a e_aᵀ`` gives dŪ/dE_aa, the off-diagonal ``½ (e_0 e_1ᵀ + e_1 e_0ᵀ)`` dŪ/d(2 E01)).
    By the envelope theorem it is the derivative of the potential the solve balanced (rods, plus
    the contacts' augmented Lagrangian with the multipliers and penalties it ended with) along any
    path of configurations that keeps C_RVE; here the affine one, every node and image mapped by
    ``√(I + 2 h change) √I⁻¹`` in the plane (the flat surface's own map is ``√I``: :func:`_form_map`,
    :func:`~yarnfit.engine.tiling.transform_images`,
    :meth:`~yarnfit.engine.contact.ContactPairs.transformed`). Frames stay as they are: they are
    balanced, so turning them changes the potential only to second order."""
    form, change = np.asarray(form, dtype=np.float64), np.asarray(change, dtype=np.float64)
    values = []
    for step in (STRAIN_SLOPE_STEP, -STRAIN_SLOPE_STEP):
        matrix = _form_map(form + 2.0 * step * change, form)
        mapped = transform_images(model, matrix)
        position = result.state.node_position @ matrix.T
        contacts = replace(result.contacts, pairs=result.contacts.pairs.transformed(matrix))
        rods = sum(internal_forces(mapped, position, result.state.edge_quaternion).terms)
        values.append(rods + contact_potential(mapped, position, contacts))
    return (values[0] - values[1]) / (2.0 * STRAIN_SLOPE_STEP * area)


def _axis_change(axis: int) -> np.ndarray:
    """``e_a e_aᵀ``: the Green strain direction of E_aa (:func:`_green_slope`)."""
    change = np.zeros((2, 2))
    change[axis, axis] = 1.0
    return change


def _transverse_slope(model: RodModel, result, axis: int, free: float, area: float) -> float:
    """dŪ/dE⊥ (J/m²) of a sample pulled along ``axis`` at the free Green strain E⊥ = ``free``
    (:func:`_green_slope` across the pull; the form's pulled entry does not enter: it is diagonal)."""
    form = np.eye(2)
    form[1 - axis, 1 - axis] = 1.0 + 2.0 * free
    return _green_slope(model, result, form, _axis_change(1 - axis), area)


def _next_free_strain(points: Sequence[_FreeStrainPoint], low: float, strain: float) -> tuple[float | None, str]:
    """The next E⊥ a uniaxial search should solve, from its converged ``points`` (E⊥ in
    ``[low, 0]``, prescribed Green strain ``strain``), or ``None`` with the search's verdict:

    - ``"minimum"``: within a bracket, the point of least slope ``s`` promises a decrease of Ū
      (``s² / 2k``, ``k`` the smaller positive secant curvature with its neighbours) below
      :data:`SEARCH_ENERGY_RTOL` and ``|s|`` is below :data:`FREE_SLOPE_RTOL` of the pure
      stretch's, or the slope's root lies within :data:`FREE_STRAIN_TOLERANCE` of it (``|s| / k``),
      or the bracket is narrower than that; or Ū does not depend on E⊥;
    - ``"upper end"``: the slope at E⊥ = 0 is not positive (the fabric would widen; the interval
      stops at 0);
    - ``"plateau"`` / ``"lower end"``: every slope is positive down to ``low``, and Ū there has
      (has not) stopped changing.

    ``points`` come in the order they were solved. A bracket (a negative slope left of a positive
    one) is narrowed by the secant step from the point of least slope (its curvature the smaller
    neighbour secant) when that lands inside the bracket, else by the secant through the bracket's
    ends as the Illinois variant of regula falsi takes it: an end kept while k ≥ 2 later points
    were solved enters with its slope halved k − 1 times (a jersey's slope, steep where its wales
    jam and flat beyond, otherwise moved one end by 5e-4 at a time). Without one the search
    steps towards where the slope points by the secant curvature of its two outermost points (by
    :data:`FREE_STRAIN_GUESS` from the pure stretch alone), at least :data:`FREE_STRAIN_PROBE`
    and, once a secant step has fallen short, at least as far as its last: a jersey's slope falls
    steeply while its wales jam and then tails off slowly, and secant steps on that tail crept
    (cotton jersey at 2 %: six steps of 5e-4 to 3e-3 towards a minimum 5e-3 away). It stops only
    with a bracket: a secant across a kink gives the jammed side's curvature, which would promise
    nothing where much is left."""
    order = {id(p): i for i, p in enumerate(points)}
    points = sorted(points, key=lambda p: p.free)
    closest = min(points, key=lambda p: abs(p.slope))
    span = max(-low, FREE_STRAIN_TOLERANCE)
    if abs(closest.slope) * span <= FLAT_ENERGY_RTOL * max(abs(closest.energy), np.finfo(float).tiny):
        return None, "minimum"
    top = points[-1]
    if top.free == 0.0 and top.slope <= 0.0:
        return None, "upper end"

    # Curvature at the point of least slope: the smaller secant with its neighbours (a secant
    # across a jersey's kink is the jammed side's, far stiffer than the slack side it stops on).
    i = points.index(closest)
    neighbours = [(points[j], points[j + 1]) for j in (i - 1, i) if 0 <= j < len(points) - 1]
    secants = [k for k in ((b.slope - a.slope) / (b.free - a.free) for a, b in neighbours) if k > 0.0]
    near_root = bool(secants) and abs(closest.slope) / min(secants) <= FREE_STRAIN_TOLERANCE
    pure = max((abs(p.slope) for p in points if p.free == 0.0), default=max(abs(p.slope) for p in points))
    settled = (bool(secants) and closest.slope**2 / (2.0 * min(secants)) <= SEARCH_ENERGY_RTOL * abs(closest.energy)
               and abs(closest.slope) <= FREE_SLOPE_RTOL * pure)

    rising = [p for p in points if p.slope > 0.0]
    right = rising[0] if rising else None
    left = next((p for p in reversed(points) if p.slope < 0.0 and (right is None or p.free < right.free)), None)
    if left is not None and right is not None:
        width = right.free - left.free
        if width <= FREE_STRAIN_TOLERANCE or near_root or settled:
            return None, "minimum"
        margin = min(0.1 * width, 0.5 * FREE_STRAIN_TOLERANCE)
        # The secant step from the point of least slope first (converges fast once near the
        # root, whatever the bracket's far end looks like: polyester jersey's bracket end beyond
        # a kink, slope −65 against ±0.05 near the root, made regula falsi creep by 5e-5 a
        # solve), if it lands inside the bracket.
        if secants:
            trial = closest.free - closest.slope / min(secants)
            if left.free + margin <= trial <= right.free - margin:
                return trial, "search"
        older = min(left, right, key=lambda p: order[id(p)])
        kept = len(order) - 1 - order[id(older)]
        slopes = [p.slope * (0.5 ** (kept - 1) if p is older and kept >= 2 else 1.0) for p in (left, right)]
        trial = left.free - slopes[0] * width / (slopes[1] - slopes[0])
        return min(max(trial, left.free + margin), right.free - margin), "search"
    # Unbracketed: every slope points the same way.
    outer, inner = (points[0], points[1:2]) if left is None else (points[-1], points[-2:-1])
    if left is None and outer.free <= low:
        falls = outer.slope * (inner[0].free - outer.free) if inner else math.inf
        return None, "plateau" if falls <= PLATEAU_RTOL * abs(outer.energy) else "lower end"
    if not inner:
        return min(max(FREE_STRAIN_GUESS * strain, low), 0.0), "search"
    inner = inner[0]
    last = outer.free - inner.free
    curvature = (inner.slope - outer.slope) / (inner.free - outer.free)
    step = -outer.slope / curvature if curvature > 0.0 else 2.0 * last
    # Not a minimum until the slope has changed sign: the curvature an unbracketed secant gives
    # can be the other side of a kink's, and promise nothing where much is left.
    shortest = abs(last) if len(points) >= 3 else FREE_STRAIN_PROBE
    step = math.copysign(max(abs(step), shortest), last)
    return min(max(outer.free + step, low), 0.0), "search"


def _solve_from(relaxed: RelaxedRepeat, form: np.ndarray, II: np.ndarray, options: QuasiStaticOptions,
                previous: tuple | None = None) -> tuple[TiledRepeat, QuasiStaticResult]:
    """``relaxed`` tiled at ``(form, II)`` (a flat sample's) and solved, warnings of a solve that
    does not converge silenced (a search's trial: its caller judges it), from the affine start or,
    with ``previous = (state, its form)``, from that equilibrium mapped by :func:`_form_map` (exact
    for its affine part, and it keeps C_RVE's values, which are linear in the
    positions). Raises :class:`TilingReachError` when the steps leave the tiles mapped."""
    tiled = tile_repeat(relaxed, form, II)
    state = tiled.state
    if previous is not None:
        prior, prior_form = previous
        matrix = _form_map(form, prior_form)
        state.node_position[:] = prior.node_position @ matrix.T
        state.edge_quaternion[:] = aligned_frames(tiled.model, state.node_position, prior.edge_quaternion)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        result = QuasiStaticSolver(tiled.model, options).solve(state, constraints=tiled.constraints)
    return tiled, result


@dataclass(frozen=True)
class _UniaxialSearch:
    """Outcome of :func:`_search_uniaxial`: the free Green strain E⊥ chosen, the solve there (its
    quasi-static result, ``None`` if none was usable) on ``tiled``, the Newton iterations of every
    trial, why it did not converge (``None`` if it did), and Ū's slope dŪ/dE⊥ at the E⊥ chosen
    (J/m²; ~0 at a minimum, the slope where the search stopped at an end of its interval; NaN
    without a converged solve there)."""

    free: float
    form: np.ndarray
    result: QuasiStaticResult | None
    tiled: TiledRepeat
    iterations: int
    failure: str | None
    free_slope: float = math.nan


def _search_uniaxial(relaxed: RelaxedRepeat, spec: SampleSpec, options: QuasiStaticOptions) -> _UniaxialSearch:
    """Find the free transverse Green strain E⊥ where Ū is least, each trial a full solve started
    from the nearest solved E⊥'s equilibrium stretched across (exact for its affine part, and it
    keeps C_RVE's values, which are linear in the positions), each solve giving Ū's slope
    dŪ/dE⊥ too (:func:`_transverse_slope`), and the trials chosen by :func:`_next_free_strain`.
    Not converged if the solve at the result did not converge, the search ran out of solves, or
    E⊥ ends at the interval's lower end still falling (the fabric would contract further)."""
    axis = spec.family.uniaxial_axis
    stretch = math.sqrt(float(spec.I[axis, axis]))
    strain = 0.5 * (stretch**2 - 1.0)
    low = max(0.5 * (SMALLEST_FREE_STRETCH**2 - 1.0), -FREE_STRAIN_RANGE * strain)
    solved: dict[float, tuple] = {}  # E⊥ -> (quasi-static result, tiled repeat, point or None if unusable)
    iterations = 0

    def form(free: float) -> np.ndarray:
        diagonal = [0.0, 0.0]
        diagonal[axis], diagonal[1 - axis] = stretch**2, 1.0 + 2.0 * free
        return np.diag(diagonal)

    def usable(e: float) -> bool:
        return solved[e][2] is not None

    def nearest_usable(free: float) -> float | None:
        warm = [e for e in solved if usable(e)]
        return min(warm, key=lambda e: abs(e - free)) if warm else None

    def solve_at(free: float) -> tuple:
        nonlocal iterations
        nearest = nearest_usable(free)
        previous = None if nearest is None else (solved[nearest][0].state, form(nearest))
        try:
            # A trial E⊥ that does not converge is a point the search does without (or approaches
            # by halves); the warning below gives the sample's verdict.
            tiled, result = _solve_from(relaxed, form(free), spec.II, options, previous)
            iterations += result.iterations
        except TilingReachError:
            # The solver's steps ran beyond the tiles mapped (a strongly squeezed width): this
            # E⊥ is unusable, and the search treats it as a wall. (The pure stretch, solved
            # first, fails as any pure sample would.)
            if not solved:
                raise
            tiled, result = tile_repeat(relaxed, form(free), spec.II), None
        point = None
        if result is not None and result.converged:
            point = _FreeStrainPoint(free, result.energy.internal / tiled.area,
                                     _transverse_slope(tiled.model, result, axis, free, tiled.area))
        return result, tiled, point

    def solve(free: float, depth: int = 0) -> None:
        outcome = solve_at(free)
        nearest = nearest_usable(free)
        if outcome[2] is None and nearest is not None and depth < FREE_STRAIN_HALVINGS:
            # Too far from the nearest equilibrium for one solve (soft yarns: a jersey's width
            # contracting by a third): solve halfway first, then again from there.
            halfway = 0.5 * (nearest + free)
            if abs(halfway - nearest) > FREE_STRAIN_TOLERANCE and halfway not in solved:
                solve(halfway, depth + 1)
                if usable(halfway):
                    outcome = solve_at(free)
        solved[free] = outcome

    solve(0.0)  # the pure stretch first: every later start is near it
    verdict = "search"
    for _ in range(FREE_STRAIN_SOLVES):
        points = [solved[e][2] for e in solved if usable(e)]
        if points:
            trial, verdict = _next_free_strain(points, low, strain)
        else:
            trial, verdict = (FREE_STRAIN_GUESS * strain, "search") if len(solved) == 1 else (None, "failed")
        if trial is None:
            break
        if trial in solved:
            # A trial that failed before: approach it from the nearest equilibrium instead.
            nearest = nearest_usable(trial)
            if nearest is None or abs(trial - nearest) <= FREE_STRAIN_TOLERANCE:
                verdict = "failed"
                break
            trial = 0.5 * (trial + nearest)
        solve(trial)
    else:
        verdict = "out of solves"
    points = [solved[e][2] for e in solved if usable(e)]
    if not points:
        free = next(iter(solved))
    elif verdict in ("upper end", "plateau", "lower end"):
        free = max(p.free for p in points) if verdict == "upper end" else min(p.free for p in points)
    else:
        least = min(p.energy for p in points)
        free = min((p for p in points if p.energy <= least + SEARCH_ENERGY_RTOL * abs(least)),
                   key=lambda p: abs(p.slope)).free
    result, tiled, _ = solved[free]
    converged = verdict in ("minimum", "upper end", "plateau")
    failure = None if converged else {
        "lower end": "the free strain reached the search interval's end with Ū still falling",
        "out of solves": "the search ran out of solves",
        "failed": "the solves near the best free strain did not converge"}[verdict]
    point = solved[free][2]
    return _UniaxialSearch(free, form(free), result, tiled, iterations, failure,
                           point.slope if point is not None else math.nan)


def _solve_uniaxial(relaxed: RelaxedRepeat, spec: SampleSpec, options: QuasiStaticOptions, start: float) -> SampleResult:
    """A uniaxial-tension sample (:func:`_search_uniaxial`): its spec carries the free strain found,
    its ``pull_slope`` the derivative of Ū in the pull's Green strain at that width
    (:func:`_green_slope`; the free strain is at Ū's minimum, so its own change adds nothing) and
    its ``across_slope`` the search's slope across the pull there."""
    search = _search_uniaxial(relaxed, spec, options)
    result, area = search.result, search.tiled.area
    if search.failure is not None:
        warnings.warn(f"uniaxial sample {spec.family} {spec.parameter:+.3g} did not converge: {search.failure} "
                      f"(E⊥ = {search.free:.4g}, {search.iterations} iterations)"
                      + ("" if result is None else f": {result.residual}"), ConvergenceWarning, stacklevel=3)
    converged = search.failure is None
    form = SampleSpec(spec.family, search.form, spec.II, spec.parameter)
    slope = math.nan
    if result is not None:
        axis = spec.family.uniaxial_axis
        slope = _green_slope(search.tiled.model, result, form.I, _axis_change(axis), area)
    return SampleResult(
        spec=form,
        energy_density=result.energy.internal / area if result is not None else math.nan,
        converged=converged,
        residual=result.residual if result is not None else Residual(math.nan, math.nan, math.nan, math.nan),
        iterations=search.iterations,
        seconds=time.perf_counter() - start,
        position=result.state.node_position if result is not None else None,
        stretch_share=stretch_share(result.energy) if result is not None else math.nan,
        pull_slope=slope,
        across_slope=search.free_slope,
    )


# A bias pull's search (:func:`_search_bias`): the pull's direction from weft (rad), and the
# largest step of its free strains per trial (Green strain): a Newton step from the pure stretch
# can promise a contraction the solver cannot reach from there in one solve.
BIAS_ANGLE = math.pi / 4
BIAS_STEP_LIMIT = 0.05
# ... and the Newton step (H⁻¹ times the slopes) below which the free strains count as found. Far
# tighter than the axis search's FREE_STRAIN_TOLERANCE: on the bias the pull's own stress is small
# against its coupling to the free strains (the plain weave at 1 %: ~0.3 N/m of force against
# ~4e4 N/m per unit of the transverse strain), so an error of 1e-5 in them moves the force by more
# than itself. Newton's last steps cost one solve each.
BIAS_STEP_TOLERANCE = 1e-7
# The probes that give the search its first Hessian, as a fraction of the pull's Green strain: the
# free strains' answer is of the pull's size (0.16–1.4 of it over the presets and the stockinette),
# and Ū is far from quadratic beyond it. The stockinette at 0.1 % probed with a fixed 1e-3 (six
# times its answer) met its loops jamming there, slopes 100x the start's; the Hessian from that
# sent the first step 50x too far and the search took 19 solves (497 Newton iterations, 2.8 s)
# where probes of a tenth of the pull take 10 (121).
BIAS_PROBE_FRACTION = 0.1


@dataclass(frozen=True)
class _BiasSearch:
    """Outcome of :func:`_search_bias`: the free Green strains ``(f, g)`` of the pull's frame
    chosen (across the pull, and the frame's shear), the first form there, its solve on ``tiled``
    (``None`` if none converged), the Newton iterations of every trial, why it did not converge
    (``None`` if it did), and Ū's slopes along ``f`` and ``g`` there (J/m²)."""

    free: np.ndarray
    form: np.ndarray
    result: QuasiStaticResult | None
    tiled: TiledRepeat | None
    iterations: int
    failure: str | None
    slopes: np.ndarray


def _search_bias(relaxed: RelaxedRepeat, strain: float, options: QuasiStaticOptions,
                 angle: float = BIAS_ANGLE) -> _BiasSearch:
    """The periodic repeat pulled to the engineering ``strain`` at ``angle`` from weft with every
    other stress free: in the pull's frame ``q`` the Green strain is ``[[e, g], [g, f]]``, ``e``
    prescribed and ``(f, g)`` where Ū is least. Off the yarn axes the two couple (a fabric pulled
    on the bias contracts and shears its own frame), so the search is a two-strain Newton on the
    envelope-theorem slopes (:func:`_green_slope` along ``q e_1 e_1ᵀ qᵀ`` and ``q (e_0 e_1ᵀ + e_1
    e_0ᵀ) qᵀ``), its Hessian from two probe solves and secant (BFGS) updates, steps at most
    :data:`BIAS_STEP_LIMIT` and halved until Ū or the slopes fall, each trial warm-started from
    the nearest equilibrium mapped by ``√I' √I⁻¹`` (which keeps C_RVE's values: they are linear in
    the positions). It starts from the pure stretch along the pull and stops when the Newton step
    is below :data:`BIAS_STEP_TOLERANCE`, or when no step lowers Ū any more and the slopes are below
    :data:`FREE_SLOPE_RTOL` of the pure stretch's with the decrease of Ū they promise below
    :data:`SEARCH_ENERGY_RTOL` of Ū; not converged otherwise or after :data:`FREE_STRAIN_SOLVES`."""
    c, s = math.cos(angle), math.sin(angle)
    q = np.array([[c, -s], [s, c]])
    pulled = 0.5 * ((1.0 + strain) ** 2 - 1.0)
    changes = (q @ np.diag([0.0, 1.0]) @ q.T, q @ np.array([[0.0, 1.0], [1.0, 0.0]]) @ q.T)
    flat = np.zeros((2, 2))
    least_free = 0.5 * (SMALLEST_FREE_STRETCH**2 - 1.0)
    iterations = 0
    solved = []  # (free (2,), result, tiled, energy, slopes (2,))

    def form(free: np.ndarray) -> np.ndarray:
        return np.eye(2) + 2.0 * q @ np.array([[pulled, free[1]], [free[1], free[0]]]) @ q.T

    def admissible(free: np.ndarray) -> bool:
        first = form(free)
        return bool(free[0] >= least_free and first[0, 0] > 0.0 and np.linalg.det(first) > 0.0)

    def solve_at(free: np.ndarray):
        nonlocal iterations
        first = form(free)
        if not solved:
            tiled, result, count = _solve_with_continuation(relaxed, first, flat, options)
            iterations += count
        else:
            nearest = min(solved, key=lambda point: float(np.abs(point[0] - free).max()))
            try:
                tiled, result = _solve_from(relaxed, first, flat, options, (nearest[1].state, form(nearest[0])))
                iterations += result.iterations
            except TilingReachError:
                return None
        if result is None or not result.converged:
            return None
        slopes = np.array([_green_slope(tiled.model, result, first, change, tiled.area) for change in changes])
        point = (np.array(free, dtype=np.float64), result, tiled, result.energy.internal / tiled.area, slopes)
        solved.append(point)
        return point

    current = solve_at(np.zeros(2))  # the pure stretch along the pull
    if current is None:
        return _BiasSearch(np.zeros(2), form(np.zeros(2)), None, None, iterations,
                           "the pure stretch along the pull did not converge", np.full(2, math.nan))
    scale, start_energy = float(np.abs(current[4]).max()), current[3]
    # The Hessian from two probes of the slopes from the pure stretch, one per free strain,
    # towards where each points, BIAS_PROBE_FRACTION of the pull's strain long.
    base, hessian = current, np.zeros((2, 2))
    for k in range(2):
        probe = np.zeros(2)
        probe[k] = -math.copysign(BIAS_PROBE_FRACTION * pulled, base[4][k] or 1.0)
        if not admissible(probe) or (point := solve_at(probe)) is None:
            return _BiasSearch(current[0], form(current[0]), current[1], current[2], iterations,
                               "a probe of the free strains did not converge", current[4])
        hessian[:, k] = (point[4] - base[4]) / probe[k]
        if point[3] < current[3]:
            current = point
    hessian = 0.5 * (hessian + hessian.T)
    failure = "the search ran out of solves"

    def balanced(point, w, v) -> bool:
        """Both slopes below FREE_SLOPE_RTOL of the pure stretch's, and the decrease of Ū they
        still promise (½ sᵀ H⁻¹ s) below SEARCH_ENERGY_RTOL of Ū, as the axis search asks: a
        knit's free minimum can lie far below its jammed pure stretch (wool jersey at 2 %: Ū 0.03
        against 2.0 J/m²), where slopes of 1 % of the pure stretch's still move Ū by a tenth."""
        promised = 0.5 * float(point[4] @ ((v / w) @ (v.T @ point[4])))
        slope = float(np.abs(point[4]).max())
        # Or Ū does not depend on the free strains at all (straight parallel yarns on the bias: a
        # line of minima at Ū = 0 to round-off), as FLAT_ENERGY_RTOL says for the axis search.
        return (slope <= FREE_SLOPE_RTOL * scale and promised <= SEARCH_ENERGY_RTOL * abs(point[3])
                or slope * BIAS_STEP_LIMIT <= FLAT_ENERGY_RTOL * abs(start_energy))

    while len(solved) < FREE_STRAIN_SOLVES:
        w, v = np.linalg.eigh(hessian)
        # A curvature that is not positive (a kink, a mechanism), or so small that the step would
        # pass the limit, is replaced by the current slopes over the limit: a step as long as the
        # limit allows. (Not the pure stretch's slopes: near a knit's free minimum Ū is far softer
        # than its jammed pure stretch, wool jersey's curvature there ~1/60 of the start's.)
        w = np.maximum(w, max(float(np.abs(current[4]).max()), np.finfo(float).tiny) / BIAS_STEP_LIMIT)
        step = -(v / w) @ (v.T @ current[4])
        step *= min(1.0, BIAS_STEP_LIMIT / float(np.abs(step).max()))
        if float(np.abs(step).max()) <= BIAS_STEP_TOLERANCE:
            failure = None
            break
        accepted = None
        while float(np.abs(step).max()) > BIAS_STEP_TOLERANCE and len(solved) < FREE_STRAIN_SOLVES:
            trial = current[0] + step
            point = solve_at(trial) if admissible(trial) else None
            # Taken if Ū falls or the slopes do: near the minimum warm-started solves land in
            # contact states whose Ū differ by more than the step changes it (the plain weave at
            # 0.1 %: 3e-7 J/m², 2.5 % of Ū), while the slopes still fall steadily.
            if point is not None and (point[3] < current[3]
                                      or float(np.abs(point[4]).max()) < float(np.abs(current[4]).max())):
                accepted = point
                break
            step = 0.5 * step
        if accepted is None:
            # No step lowers Ū: its changes are round-off here. Found if the slopes are as small
            # as the axis search asks (balanced); else the search is stuck.
            failure = None if balanced(current, w, v) else "no step of the free strains lowered Ū"
            break
        moved, change = accepted[0] - current[0], accepted[4] - current[4]
        if float(moved @ change) > 0.0:  # BFGS keeps the Hessian positive definite
            hs = hessian @ moved
            hessian = hessian - np.outer(hs, hs) / float(moved @ hs) + np.outer(change, change) / float(moved @ change)
        current = accepted
    return _BiasSearch(current[0], form(current[0]), current[1], current[2], iterations, failure, current[4])


@dataclass(frozen=True)
class PeriodicPull:
    """The periodic fabric pulled along weft, warp or the bias with every other stress free: what
    a uniaxial-tension sample gives a tensile test (:func:`periodic_pull`,
    :func:`periodic_bias_pull`).

    Attributes:
        direction: ``"weft"``, ``"warp"`` or ``"bias"`` (45° from weft).
        strain: the pull's engineering strain λ − 1.
        force_n_per_m: force per reference width, dŪ/dλ (N/m).
        width_ratio: the distance between the strip's long edges (which stay lines along the
            pull) over the reference width, ``√det I / λ``: the free transverse stretch μ along
            weft or warp.
        converged: the sample converged (its solve and the free-strain search).
        residual: the solve's residuals at the result.
        iterations: Newton iterations over every trial of the search.
        seconds: wall time (s).
    """

    direction: str
    strain: float
    force_n_per_m: float
    width_ratio: float
    converged: bool
    residual: Residual
    iterations: int
    seconds: float


def periodic_pull(relaxed: RelaxedRepeat, axis: int, strain: float,
                  options: QuasiStaticOptions | None = None) -> PeriodicPull:
    """The infinite fabric of ``relaxed`` pulled to the engineering ``strain`` (λ − 1) along
    ``axis`` (0 weft, 1 warp) with the other direction free: the uniaxial-tension sample
    (:func:`_solve_uniaxial`) and its force per reference width ``dŪ/dλ = λ dŪ/dE`` (N/m), ``λ``
    times the sample's ``pull_slope``. The yarn-level reference a cut strip converges to as it
    widens, and that the fitted shell's :meth:`~yarnfit.shell.ShellMaterial.uniaxial_pull` should
    follow. Warns :class:`~yarnfit.engine.ConvergenceWarning` when the sample does not converge."""
    if axis not in (0, 1):
        raise ValueError(f"axis must be 0 (weft) or 1 (warp), got {axis!r}")
    family = next(f for f in UNIAXIAL_FAMILIES if f.uniaxial_axis == axis)
    return _periodic_pull(relaxed, family, ("weft", "warp")[axis], strain, options)


def _periodic_pull(relaxed: RelaxedRepeat, family: Family, direction: str, strain: float,
                   options: QuasiStaticOptions | None) -> PeriodicPull:
    """:class:`PeriodicPull` ``direction`` of the uniaxial ``family``'s sample at ``strain``
    (:func:`solve_sample`): force ``λ`` times its ``pull_slope``; width the free transverse
    stretch along a yarn axis, ``√det I / λ`` off it."""
    strain = positive_number(strain, "strain")
    start = time.perf_counter()
    sample = solve_sample(relaxed, SampleSpec.at(family, strain), options)
    stretch = 1.0 + strain
    if not math.isfinite(sample.pull_slope):
        width = math.nan
    elif family.uniaxial_axis is not None:
        width = math.sqrt(sample.I[1 - family.uniaxial_axis, 1 - family.uniaxial_axis])
    else:
        width = math.sqrt(float(np.linalg.det(sample.I))) / stretch
    return PeriodicPull(direction, strain, stretch * sample.pull_slope, width, sample.converged, sample.residual,
                        sample.iterations, time.perf_counter() - start)


def _solve_bias(relaxed: RelaxedRepeat, spec: SampleSpec, options: QuasiStaticOptions, start: float) -> SampleResult:
    """A uniaxial-tension sample off the yarn axes (:func:`_search_bias` at the family's angle):
    its spec carries the form found, its ``pull_slope`` dŪ/de along the pull (:func:`_green_slope`)
    and its ``across_slope`` the search's slope along the transverse strain (the pull frame's
    shear is free too: its slope is ~0 where the search converged)."""
    angle = spec.family.uniaxial_angle
    search = _search_bias(relaxed, spec.parameter, options, angle)
    if search.failure is not None:
        warnings.warn(f"uniaxial sample {spec.family} {spec.parameter:+.3g} did not converge: {search.failure}"
                      + ("" if search.result is None else f": {search.result.residual}"), ConvergenceWarning,
                      stacklevel=3)
    result = search.result
    if result is None:
        return SampleResult(spec=spec, energy_density=math.nan, converged=False,
                            residual=Residual(math.nan, math.nan, math.nan, math.nan), iterations=search.iterations,
                            seconds=time.perf_counter() - start)
    direction = np.array([math.cos(angle), math.sin(angle)])
    area = search.tiled.area
    return SampleResult(
        spec=SampleSpec(spec.family, search.form, spec.II, spec.parameter),
        energy_density=result.energy.internal / area,
        converged=search.failure is None,
        residual=result.residual,
        iterations=search.iterations,
        seconds=time.perf_counter() - start,
        position=result.state.node_position,
        stretch_share=stretch_share(result.energy),
        pull_slope=_green_slope(search.tiled.model, result, search.form, np.outer(direction, direction), area),
        across_slope=float(search.slopes[0]),
    )


def periodic_bias_pull(relaxed: RelaxedRepeat, strain: float,
                       options: QuasiStaticOptions | None = None) -> PeriodicPull:
    """The infinite fabric of ``relaxed`` pulled to the engineering ``strain`` (λ − 1) on the bias
    (45° from weft) with every other stress free: the bias uniaxial sample (:func:`_solve_bias`:
    the transverse strain and the pull frame's shear both free) and its force per reference width
    ``λ dŪ/de`` (N/m), ``e`` the pull's Green strain, ``λ`` times the sample's ``pull_slope``. The
    reference a cut bias strip converges to as it widens. Warns
    :class:`~yarnfit.engine.ConvergenceWarning` when the search does not converge."""
    return _periodic_pull(relaxed, Family.BIAS_UNIAXIAL, "bias", strain, options)


# -- sample ranges --------------------------------------------------------------------------------

# Largest curvature times repeat size (rad): keeps the saddles' Gauss defect (~κ² p² / 16 of
# strain at the repeat's corners) small. Measured on cotton twill, a saddle's Ū/κ² grows by 4 %
# from 0.05 to 0.2 rad per repeat and by 10 % to 0.4 rad; single and dome bends by under 2 %.
MAX_TURN_PER_REPEAT = 0.25



def default_ranges(relaxed: RelaxedRepeat) -> SampleRanges:
    """What the fibre can bear: stretch up to its breaking strain, curvature up to the one that
    strains a yarn's surface fibres to breaking (``ε_max / r``), and no more than
    MAX_TURN_PER_REPEAT across one repeat."""
    strain = relaxed.fiber.breaking_strain
    curvature = min(strain / relaxed.radius, MAX_TURN_PER_REPEAT / float(max(relaxed.repeat_size)))
    return SampleRanges(stretch=strain, curvature=curvature)


# -- many samples in parallel ---------------------------------------------------------------------


def sample_tasks(relaxed, specs: Sequence[SampleSpec], key: Callable[[int], object] = lambda i: i,
                 label: str = "") -> list[Task]:
    """One :class:`~yarnfit.tasks.Task` per sample: ``solve_sample(relaxed, spec)`` keyed
    ``key(i)``, ranked so that the longest start first (the uniaxial searches, 5–15 solves each;
    then the membrane samples by strain, large stretches taking the most Newton iterations; then
    the bends). ``relaxed`` may be a :class:`~yarnfit.tasks.Result` placeholder (a catalogue's
    relaxation task)."""
    order = sorted(range(len(specs)), key=lambda i: _expected_cost(specs[i]), reverse=True)
    rank = {i: len(specs) - r for r, i in enumerate(order)}
    return [Task(key(i), solve_sample, (relaxed, spec), cost=rank[i],
                 label=f"{label}sample {i + 1}/{len(specs)} ({spec.family} {spec.parameter:+.3g})")
            for i, spec in enumerate(specs)]


def solve_samples(
    relaxed: RelaxedRepeat,
    specs: Sequence[SampleSpec],
    workers: int | None = None,
    on_sample: Callable[[int, int, SampleResult], None] | None = None,
    backend: Backend | None = None,
) -> list[SampleResult]:
    """Solve every sample on ``backend`` (default: a :class:`~yarnfit.tasks.LocalPool` of
    ``workers`` processes, every core by default; 1 runs in this process). ``on_sample(done,
    total, result)`` is called as each finishes. Results come back in the order of ``specs``.

    A sample whose solve raises makes this raise it (after the others finished); Ctrl-C stops the
    workers and raises ``KeyboardInterrupt`` (:mod:`yarnfit.tasks`)."""
    if backend is None:
        workers = (os.cpu_count() or 1) if workers is None else int(workers)
        if workers < 1:
            raise ValueError(f"workers must be at least 1, got {workers}")
        with LocalPool(min(workers, max(1, len(specs)))) as pool:
            return solve_samples(relaxed, specs, on_sample=on_sample, backend=pool)

    def done(task, outcome, count, total):
        if on_sample is not None and not isinstance(outcome, BaseException):
            on_sample(count, total, outcome)

    outcomes = run_tasks(sample_tasks(relaxed, specs), backend, on_done=done)
    for i in range(len(specs)):
        if isinstance(outcomes[i], BaseException):
            raise outcomes[i]
    return [outcomes[i] for i in range(len(specs))]


def _expected_cost(spec: SampleSpec) -> tuple:
    """Sort key of a sample's expected solve time (larger first): uniaxial searches, then membrane
    samples by strain, then bends by curvature."""
    strain = float(np.abs(spec.I - np.eye(2)).max())
    return (spec.family.uniaxial_angle is not None, float(np.abs(spec.II).max()) == 0.0, strain,
            float(np.abs(spec.II).max()))
