"""Phase 1 (paper §4.5): relax a periodic yarn repeat into the rest state homogenization starts from.

Every yarn of the pattern becomes a closed periodic rod (its closing edge runs into the
neighbouring tile); rest lengths are the pattern's rest lengths (the initial edge lengths of a
generated geometry) times the shrink factor (0.8 knits, 0.9 wovens; 1 for a ``.pyp`` file used as
written, whose rest lengths are already relaxed ones) and the rest shape is straight and
untwisted. The quasi-static solver finds the
equilibrium with contacts between all yarns and all their periodic images, the repeat keeping its
size. The relaxed configuration then becomes the rest state: rest lengths and curvatures of the
relaxed yarns (frames turned onto their edges, removing the tiny equilibrium shear).

That rest state is then **settled** (:func:`settle_rest_state`): solved once more in its own rest
model under the constraints every homogenization sample has (each yarn's centroid held), and the
equilibrium made the rest state again, :data:`REST_SETTLES` times at most. The relaxation samples
its contacts at points spaced along its own (shrunk) rest lengths; the rest model, whose rest
lengths are the relaxed ones, samples them elsewhere, and between the relaxation's points yarns
overlap by up to ~0.2 % of the diameter, within its tolerance. Without the settle every sample
began by pushing those overlaps apart, with no elastic force to resist but the one it was
creating: HYLC's stockinette (polyester, as written) stored 1.8e-3 J/m² in the undeformed sample,
more than the 0.1 % weft and warp samples did (1.1e-3 and 5.7e-5 J/m²), so the smallest samples
read the release of that stored energy rather than the fabric's stiffness, and every sample spent
its first ~20 Newton iterations on it. One settle left 1.8e-4 J/m², three 3.8e-5: what remains is
the contact ramp's smoothing band (``yarnfit.engine.contact_lagrangian.CONTACT_SMOOTHING``), whose
fresh multipliers push touching yarns apart by up to 1e-4 of the radius sum.

For a fabric given by areal density, the yarn radius is the fixed point of
``r = sqrt(ρ_fabric p_x p_y / (ρ_yarn L π))`` with ``L`` the *relaxed* yarn length and
``ρ_yarn = φ ρ_fibre``, so the relaxed repeat carries the stated g/m² (a relaxation or two more
than the first). The rods' rigidities are the :class:`~yarnfit.yarn.Yarn`'s at that radius.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

from .engine import (
    ConvergenceWarning,
    EnergyTerms,
    LinearConstraints,
    Progress,
    QuasiStaticOptions,
    QuasiStaticSolver,
    Residual,
    Rod,
    RodModel,
    RodSection,
    RodState,
    aligned_frames,
    energy,
)
from .engine.contact import max_penetration
from .engine.model import quaternion_d1
from .fabric import SHRINK, Fabric, radius_from_areal_density
from .fibers import Fiber
from .patterns import YarnPattern
from .yarn import Yarn, YarnConstruction

# The radius fixed point stops when r changes by less than this; the areal density then matches
# to about twice as much (it goes as r²), well inside the 0.5 % the relaxed repeat is checked to.
RADIUS_TOLERANCE = 1e-3
RADIUS_RELAXATIONS = 6
# Newton iterations allowed per relaxation. Generated repeats take 15–130; HYLC's jammed
# cartridge-belt rib (356 nodes, ~4000 loaded contact samples, starting 5 % overlapped) takes ~300,
# most of them re-balancing after each penalty stiffening. The limit only stops a run that is
# going nowhere.
MAX_ITERATIONS = 1000
# Largest overlap of two yarns (fraction of the diameter, true segment distances) a relaxed repeat
# may keep. The solver drives its sampled contact gaps to 1e-5; between samples a crossing hides
# at most 0.2 %, so a valid relaxation stays far below this.
OVERLAP_TOLERANCE = 0.01
# Settles of the rest state (see the module docstring): each is a solve from the rest state, its
# equilibrium the next rest state. The first removes the contact sampling's overlaps (stockinette:
# 24 Newton iterations, stored energy 1.8e-3 -> 1.8e-4 J/m²); later ones take 3-5 iterations and
# shrink what the smoothing band stores roughly as 1/k (9e-5, 3.8e-5 J/m²).
REST_SETTLES = 3


def pattern_rods(pattern: YarnPattern, section: RodSection, shrink: float) -> list[Rod]:
    """One closed periodic rod per yarn, in the order of ``pattern.yarns()``: straight rest shape,
    rest lengths ``shrink`` × the edge lengths, nothing pinned (see :func:`free_motion_constraints`)."""
    return [
        Rod(points=pattern.node_position[yarn.nodes], radius=pattern.radius, material=section, closed=True,
            tile_offsets=yarn.tiles, rest_lengths=rest, straight=True, name=f"yarn {k}")
        for k, (yarn, rest) in enumerate(zip(pattern.yarns(), _rest_lengths(pattern, shrink)))
    ]


def _rest_lengths(pattern: YarnPattern, shrink: float) -> list[np.ndarray]:
    """Per yarn, ``shrink`` times the pattern's rest lengths (its edge lengths, for a generated
    pattern or a rescaled file)."""
    return [shrink * pattern.rest_length[yarn.nodes] for yarn in pattern.yarns()]


def free_motion_constraints(model: RodModel) -> LinearConstraints:
    """Constraints of the phase-1 relaxation: the free motions of a periodic repeat, and the yarn
    spacing the label gives.

    - Per yarn, the mean of its nodes along its own direction: a periodic yarn can slide along
      itself (its material points move along the curve, which maps the yarn onto itself), so this
      mean only labels which material sits where.
    - Per yarn, the mean of its nodes across it in the fabric plane: the thread counts set the
      spacing of the yarns. Without friction nothing else holds a yarn in its place (a 2/1 twill's
      wefts slide along the crimp of the warps until they jam); real fabrics hold it by friction,
      which the quasi-static solve does not model.
    - The mean of all nodes along the normal (the repeat may translate out of plane), and, along a
      tile vector that every yarn runs along (x in a weft knit, where the geometry could translate
      while the yarns slide back), one node's coordinate.
    - Per yarn, the spin of its first frame about its tangent: with a straight, isotropic rest
      shape, turning all of a closed yarn's frames about their tangents costs nothing.
    """
    n = model.n_nodes
    normal = np.cross(model.lattice[0], model.lattice[1])
    normal /= np.linalg.norm(normal)
    rows = []

    def mean_row(direction: np.ndarray, rods) -> np.ndarray:
        row = np.zeros((n, 3))
        nodes = np.concatenate([np.arange(model.rod_node_start[r], model.rod_node_start[r + 1]) for r in rods])
        row[nodes] = direction / len(nodes)
        return row.ravel()

    axes = []
    for r in range(model.n_rods):
        direction = model.rod_period[r] @ model.lattice
        if not np.any(direction):
            continue
        axis = direction / np.linalg.norm(direction)
        axes.append(axis)
        rows.append(mean_row(axis, [r]))
        rows.append(mean_row(np.cross(normal, axis), [r]))
    rows.append(mean_row(normal, range(model.n_rods)))
    for tile_vector in model.lattice:
        e = tile_vector / np.linalg.norm(tile_vector)
        if all(abs(a @ e) > 0.5 for a in axes):
            row = np.zeros((n, 3))
            row[0] = e
            rows.append(row.ravel())
    return LinearConstraints(np.array(rows), spin_edges=model.rod_edge_start[:-1])


@dataclass(frozen=True)
class RelaxedRepeat:
    """A relaxed periodic repeat (phase 1 result).

    Attributes:
        name: label.
        fiber: the fibre.
        yarn: the yarn at the relaxation's radius (its rigidities are the rods').
        pattern: the unrelaxed input pattern (at the relaxation's radius and repeat size).
        model: the rod model whose rest state is the relaxed configuration (rest lengths and
            curvatures of the relaxed yarns; nothing pinned, see :func:`free_motion_constraints`).
        relaxation_model: the model that was relaxed (straight rest shape, shrunk rest lengths);
            ``state`` is its equilibrium.
        state: the rest state of ``model`` (positions ``(N, 3)`` m, frames ``(E, 4)``): the
            relaxed configuration after its settles (see :func:`settle_rest_state`).
        relaxation_state: the equilibrium of ``relaxation_model`` (before the settles).
        shrink: the rest-length factor used.
        converged: the solve met every tolerance.
        iterations: Newton iterations of the last relaxation.
        residual: its final residuals.
        energy: phase-1 energy at equilibrium (J), before the rest state was reset.
        penetration: worst overlap of two yarns, relative to the diameter.
        seconds: wall time of all relaxations (s).
        relaxations: relaxations run (more than one when the radius follows the relaxed length).
        settles: settles of the rest state used (converged ones).
        settle_energy: rod energy (J) the last settle stored, i.e. how far the rest state was
            from an equilibrium of its own model when it was last reset (0 if the last settle took
            no Newton step).
    """

    name: str
    fiber: Fiber
    yarn: Yarn
    pattern: YarnPattern
    model: RodModel
    relaxation_model: RodModel
    state: RodState
    relaxation_state: RodState
    shrink: float
    converged: bool
    iterations: int
    residual: Residual
    energy: EnergyTerms
    penetration: float
    seconds: float
    relaxations: int = 1
    settles: int = 0
    settle_energy: float = 0.0

    @property
    def radius(self) -> float:
        return self.pattern.radius

    @property
    def valid(self) -> bool:
        """Converged, and no two yarns overlap by more than OVERLAP_TOLERANCE of the diameter."""
        return self.converged and self.penetration <= OVERLAP_TOLERANCE

    @property
    def repeat_size(self) -> np.ndarray:
        return self.pattern.repeat_size

    @property
    def yarn_length(self) -> float:
        """Relaxed yarn length in one repeat (m)."""
        return float(self.model.edge_rest_length.sum())

    @property
    def yarn_length_per_area(self) -> float:
        """Relaxed yarn length per fabric area (m/m²)."""
        return self.yarn_length / float(np.prod(self.repeat_size))

    @property
    def areal_density(self) -> float:
        """Areal density of the relaxed repeat, ``φ ρ_fibre π r² L / (p_x p_y)`` (kg/m²)."""
        return self.yarn.mass_per_length * self.yarn_length_per_area

    def relaxed_pattern(self) -> YarnPattern:
        """The relaxed repeat as a :class:`YarnPattern`, e.g. to write a ``.pyp`` file: relaxed
        positions, the rest lengths they balance (the shrunk ones) and the relaxed frames' ``d1``
        as reference directors. Relaxing it again as written (shrink 1) reproduces the same
        equilibrium."""
        m, state = self.relaxation_model, self.relaxation_state
        position = np.empty_like(self.pattern.node_position)
        rest_length = np.empty(self.pattern.n_nodes)
        director = np.empty((self.pattern.n_nodes, 3))
        d1 = quaternion_d1(state.edge_quaternion)
        for r, nodes in enumerate(_rod_nodes(self.pattern)):
            position[nodes] = state.node_position[m.rod_nodes(r)]
            rest_length[nodes] = m.edge_rest_length[m.rod_edges(r)]
            director[nodes] = d1[m.rod_edges(r)]
        return replace(self.pattern, node_position=position, rest_length=rest_length, reference_director=director,
                       node_twist=np.zeros(self.pattern.n_nodes))


def relax_pattern(
    pattern: YarnPattern,
    fiber: Fiber,
    shrink: float | None = None,
    options: QuasiStaticOptions | None = None,
    on_iteration: Callable[[Progress], None] | None = None,
    name: str | None = None,
    yarn: YarnConstruction | None = None,
) -> RelaxedRepeat:
    """Relax ``pattern`` made of ``fiber`` yarns (phase 1), the yarns made as ``yarn`` (default:
    the fibre-assembly model) with the pattern's radius as contact radius. ``shrink`` defaults to
    the pattern family's (0.8 knits, 0.9 wovens); ``on_iteration`` receives the solver's
    :class:`Progress` after every iteration (node positions in the order of ``pattern.yarns()``)."""
    shrink = SHRINK[pattern.family] if shrink is None else float(shrink)
    if not 0.0 < shrink <= 1.0:
        raise ValueError(f"shrink factor must lie in (0, 1], got {shrink!r}")
    start = time.perf_counter()
    built_yarn = Yarn.build(fiber, yarn or YarnConstruction(), pattern.radius)
    rods = pattern_rods(pattern, built_yarn.section(), shrink)
    phase1 = RodModel.from_rods(rods, lattice=pattern.lattice)
    options = options or QuasiStaticOptions(max_iterations=MAX_ITERATIONS)
    result = QuasiStaticSolver(phase1, options).solve(RodState.from_model(phase1), callback=on_iteration,
                                                       constraints=free_motion_constraints(phase1))
    # The relaxed configuration (frames turned onto their edges) becomes the rest state, settled.
    model = rest_model(rods, phase1, result.state, pattern.lattice)
    model, settles, settle_energy = settle_rest_state(model, rods, pattern.lattice, options)
    state = RodState.from_model(model)
    return RelaxedRepeat(
        name=name or pattern.name,
        fiber=fiber,
        yarn=built_yarn,
        pattern=pattern,
        model=model,
        relaxation_model=phase1,
        state=state,
        relaxation_state=result.state,
        settles=settles,
        settle_energy=settle_energy,
        shrink=shrink,
        converged=result.converged,
        iterations=result.iterations,
        residual=result.residual,
        energy=result.energy,
        penetration=max_penetration(model, state.node_position),
        seconds=time.perf_counter() - start,
    )


def rest_model(rods: list[Rod], solved: RodModel, state: RodState, lattice: np.ndarray) -> RodModel:
    """The model whose rest state is ``state`` (an equilibrium of ``solved``, built from ``rods``
    in the same order): each rod's points and frames (turned onto their edges) taken from
    ``state``, its rest lengths and curvatures from them."""
    frames = aligned_frames(solved, state.node_position, state.edge_quaternion)
    return RodModel.from_rods([replace(rod, points=state.node_position[solved.rod_nodes(r)],
                                       frames=frames[solved.rod_edges(r)], rest_lengths=None, straight=False)
                               for r, rod in enumerate(rods)], lattice=lattice)


def yarn_centroid_constraints(model: RodModel, frame: np.ndarray | None = None) -> LinearConstraints:
    """Per yarn and axis k, ``Σ_j (R_jᵀ x_j)_k`` keeps its value, ``R_j`` the ``(N, 3, 3)``
    ``frame`` of node j (identity if None). With the surface frames of a deformed sample these are
    the homogenization's ``C_RVE`` (:mod:`yarnfit.homogenize`); with none, they hold each yarn's
    centroid, which is what ``C_RVE`` holds of the undeformed repeat."""
    rows = np.zeros((3 * model.n_rods, model.n_nodes, 3))
    for r in range(model.n_rods):
        nodes = np.arange(model.rod_node_start[r], model.rod_node_start[r + 1])
        for k in range(3):
            rows[3 * r + k, nodes] = np.eye(3)[k] if frame is None else frame[nodes, :, k]
    return LinearConstraints(rows.reshape(3 * model.n_rods, -1))


def settle_rest_state(model: RodModel, rods: list[Rod], lattice: np.ndarray,
                      options: QuasiStaticOptions) -> tuple[RodModel, int, float]:
    """Settle the rest state of ``model`` (built from ``rods``) into an equilibrium of its own
    contacts, as the module docstring says: up to :data:`REST_SETTLES` solves from the rest state
    with each yarn's centroid held, each equilibrium the next rest state. Stops early when a solve
    takes no Newton step. A settle that does not converge is not used (its warning says why).
    Returns ``(model, settles used, rod energy (J) the last one stored)``."""
    settles, stored = 0, 0.0
    for settles in range(1, REST_SETTLES + 1):
        state = RodState.from_model(model)
        with warnings.catch_warnings():
            # Said below, with what it means for the rest state.
            warnings.simplefilter("ignore", ConvergenceWarning)
            solved = QuasiStaticSolver(model, options).solve(state, constraints=yarn_centroid_constraints(model))
        if not solved.converged:
            warnings.warn(f"settle {settles} of the rest state did not converge ({solved.residual}); the rest state "
                          f"is the one before it" + (" (contacts overlapping as the relaxation left them)"
                                                     if settles == 1 else ""), ConvergenceWarning, stacklevel=3)
            settles -= 1
            break
        stored = solved.energy.internal
        if solved.iterations == 0:
            break
        model = rest_model(rods, model, solved.state, lattice)
    return model, settles, stored


def relax(
    fabric: Fabric,
    options: QuasiStaticOptions | None = None,
    on_iteration: Callable[[Progress], None] | None = None,
    on_start: Callable[[YarnPattern], None] | None = None,
) -> RelaxedRepeat:
    """Relax the repeat of ``fabric``, with the radius that gives its areal density in the relaxed
    state (see the module docstring). ``on_start(pattern)`` is called before each relaxation (the
    radius changes between them), ``on_iteration`` after every solver iteration."""
    start = time.perf_counter()
    length = None
    for attempt in range(1, RADIUS_RELAXATIONS + 1):
        pattern = fabric.pattern(length_override=length)
        if on_start is not None:
            on_start(pattern)
        result = relax_pattern(pattern, fabric.fiber, fabric.shrink, options, on_iteration, name=fabric.name,
                               yarn=fabric.yarn)
        # An unconverged length says nothing about the radius: stop, and report the relaxation.
        if fabric.areal_density is None or not result.converged:
            break
        radius = radius_from_areal_density(fabric.areal_density, fabric.yarn_density, pattern.repeat_size,
                                           result.yarn_length)
        if abs(radius / pattern.radius - 1.0) < RADIUS_TOLERANCE:
            break
        length = result.yarn_length
    return replace(result, seconds=time.perf_counter() - start, relaxations=attempt)


def relaxed_energy(relaxed: RelaxedRepeat) -> EnergyTerms:
    """Energy of the relaxed state in its own rest model (zero up to round-off)."""
    return energy(relaxed.model, relaxed.state)


def _rod_nodes(pattern: YarnPattern) -> list[np.ndarray]:
    return [yarn.nodes for yarn in pattern.yarns()]
