"""The full yarn-level stretch test (issue 6, item 2): a FAB-style strip cut from an explicit yarn
swatch, pulled quasi-statically in the yarn engine, no periodicity.

How the swatch is made (:func:`cut_swatch`): every yarn of the relaxed repeat is unrolled along
its period (node j of copy m at ``x_j + (C_j + m P + T) @ lattice``, ``C_j`` its chain tile, ``P``
the yarn's period, ``T`` the tile of the copy), copies at every tile that is not the same yarn
shifted along itself, and cut by a rectangle of the fabric plane whose long axis ``u`` makes the
angle of the strip's direction with the weft (0° weft, 90° warp, 45° bias). Each run of
consecutive nodes inside the rectangle becomes an **open rod** (yarn ends cut at the boundary);
runs shorter than half the repeat's smaller side are dropped (clipped loop fragments would float
free). Rest lengths and frames are the relaxed repeat's, so the rest shape of every piece is its
relaxed shape and the uncut swatch at zero strain is force-free (contacts just touching). The
swatch is then turned so that ``u`` is world x, ``v`` (across) world y; z is the fabric normal.

The test (:func:`stretch_swatch`): nodes within ``clamp`` of either short end are pinned (and the
frames of edges with both nodes pinned: the jaws hold the yarn), the ``+u`` jaw is moved by
``strain × gauge`` (``gauge`` = strip length minus both bands) along x, and each strain is a
converged Newton solve (:class:`yarnfit.engine.QuasiStaticSolver`, stopping on force/torque
residuals, energy change and contact penetration; never a fixed iteration count, see
``docs/design.md`` §5), warm-started from the previous strain's equilibrium stretched affinely
between the jaws (an x-stretch never brings two segments closer, so the guess adds no overlap).
The validation scene (:func:`run_yarn`) pulls with Coulomb friction at the yarn contacts, the
fibre's coefficient, each strain reached in lagged frictional load steps of at most
:data:`~yarnfit.engine.lagged.FRICTION_STRAIN_STEP` (:mod:`yarnfit.engine.friction`): the yarn ends cut at a strip's
long sides are held by friction, as a real strip's are; frictionless, they slide in freely and
the strip stays soft at any width (``docs/design.md`` §3).

Outputs per direction and strain (what the test reads off the strip is
:mod:`yarnfit.validate.strip`):

- ``force_n_per_m``: the pull on the moving jaw (the x component of the sum over its pinned nodes
  of ∂Π/∂x, Π the rod energy plus the contact potential: the force the jaw must apply) divided by
  the initial strip width; ``fixed_force_n_per_m`` the same on the fixed jaw (minus sign: it pulls
  back), equal and opposite at equilibrium; ``rod_force_n_per_m`` the rods' part alone
  (``contact_share`` the rest).
- ``middle_force_n_per_m``: the pull the middle half of the width carries across planes over the
  middle half of the gauge (:func:`~yarnfit.validate.strip.cut_forces`: the rod elements, contact
  pairs and friction anchors of that band crossing each plane), mean over
  :data:`~yarnfit.validate.strip.CUT_PLANES` planes, divided by half the initial width
  (``middle_force_range_n_per_m`` its least and largest plane); the force of the strip where it
  is furthest from its cut sides and jaws. ``cut_force_n_per_m`` the same over the whole width:
  the jaws' pull, to the solve's residual; ``quarter_forces_n_per_m`` each quarter's from −y to
  +y, per quarter width (the profile across the strip). Cut yarn ends at the long sides carry
  little, so a strip's middle pulls more than its jaws say (a 4 × 3 repeat cotton jersey bias
  strip 1.7 times, 16 × 8 knit strips 1.3–1.9 times).
- ``mid_strain``: the strain of the strip's middle half, where it is furthest from the jaws, read
  between two material marks as an extensometer reads it
  (:func:`~yarnfit.validate.strip.mid_strain`; null where a mark holds no node): beside
  ``compression_ratio`` (measured at mid-length too), the strip's own state where it is most
  nearly uniform, which a free pull at that strain should match.
- ``middle_compression_ratio``: the width ratio of the strip's middle half
  (:func:`~yarnfit.validate.strip.middle_compression`: two material marks a half width apart,
  across the middle half of the gauge; null where a mark holds no node), the compression where
  the strip is uniform, beside ``middle_force_n_per_m``.
- ``compression_ratio``: width at mid-length over the initial width, the width being the span
  across the strip of the points where yarn centrelines cross the mid-length plane (at more than
  30° from it), plus one diameter (:func:`~yarnfit.validate.strip.mid_width`; yarns lying along
  the plane and their loose cut ends at the long sides do not count); ``extent_ratio`` the same
  from every node within a quarter width of mid-length
  (:func:`~yarnfit.validate.strip.extent_width`: cut ends splaying out count); ``edge_draw_in_m``
  how far the yarn ends cut at the long sides lie inside where the strip's narrowing puts them
  (:func:`~yarnfit.validate.strip.edge_draw_in`: yarn slid in from the sides; null where none is
  cut in the middle half of the gauge).
- ``steps``: the middle's reading after each load step (the last is the point's own): its
  ``strain`` (the jaws'), ``mid_strain``, ``middle_force_n_per_m``, ``middle_compression_ratio``,
  ``compression_ratio`` and ``converged``: the curve of the strip's uniform part between the reported strains, which
  :func:`read_uniform` reads at the strains its middle reached.
- the solver's residuals, iterations and wall time, and ``load_steps``; with friction
  (``stretch_swatch(..., friction=μ)``, off by default), ``slowest_step_seconds``,
  ``friction_passes`` and ``friction_change``, the slowest load step's wall time, the lagged passes
  and the last step's last change of the anchored normal force
  (:func:`yarnfit.engine.lagged.lagged_solve`).

Recording (:class:`SwatchRecording`, one ``rr.RecordingStream`` per file as in
:mod:`yarnfit.record`, application id ``yarnfit``), default ``logs/<material>/yarn.rrd``.
Timeline ``strain`` (sequence): step k is the k-th solved strain of a direction, counting on
across directions (0 is the unstrained swatch of the first direction). Entity paths (m, 3D: x
the pull, y across, z the fabric normal):

- ``yarn``: ``ViewCoordinates`` right-handed, z up (static).
- ``yarn/swatch/yarns``: ``LineStrips3D``, one strip per cut yarn piece (its nodes in order),
  radius = yarn radius, grey for pieces starting in a jaw and blue for the others, at each step.
- ``yarn/plots/force_<direction>``: ``Scalars``, pull per unit width (N/m) at that direction's
  steps.
- ``yarn/plots/middle_force_<direction>``: ``Scalars``, the middle half's pull per unit width
  (N/m, ``middle_force_n_per_m``).
- ``yarn/plots/compression_<direction>``: ``Scalars``, compression ratio (dimensionless).
- ``yarn/plots/strain``: ``Scalars``, the nominal strain of the step (dimensionless).
- ``yarn/summary``: ``TextDocument`` (markdown), the table of results (static, by ``finish``).

``<direction>`` is each of ``weft``, ``warp``, ``bias`` that was run.
"""

from __future__ import annotations

import math
import os
import time
import warnings
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
import rerun as rr
import rerun.blueprint as rrb
from scipy.spatial.transform import Rotation

from ..checks import positive_number
from ..engine import (
    ConvergenceWarning,
    QuasiStaticOptions,
    QuasiStaticResult,
    QuasiStaticSolver,
    Rod,
    RodMaterial,
    RodSection,
    RodModel,
    RodState,
    energy_gradient,
)
from ..engine.contact_lagrangian import ContactSet
from ..engine.lagged import (FRICTION_STRAIN_STEP, STEP_HALVINGS, LaggedSolve, in_halves, lagged_solve,
                             load_step_count)
from ..engine.rotations import as_frames, as_rotations, quaternion_between
from ..engine.tiling import YarnPiece, cut_rectangle
from ..jsonfile import finite_or_none
from ..material_file import MaterialFile
from ..record import Recording, folded_panels, markdown_table
from . import PULL_DIRECTIONS, SceneResult
from .checkpoint import LevelTotals, PullCheckpoint, pull_fingerprint
from .strip import (Swatch, cut_forces, edge_draw_in, extent_width, free_side_ends, mid_strain, mid_width,
                    middle_compression)

# The strains the FAB-style test reports (nominal engineering strain of the gauge).
STRAINS = (0.02, 0.05, 0.10)
# Strip size in repeats of the larger repeat side: gauge length, width and each jaw's band. Cost
# on one core (cotton twill, weft strip, 2 % from rest): 8.2 × 5.5 mm between the jaws (8357 nodes)
# took 217 Newton iterations, 317 s; the full size below (5.5 × 4.1 mm, 4149 nodes) 93 iterations,
# 40 s. A strip of FAB's 8 × 5 cm would be 100 times that many nodes. Quick is for CI.
FULL_SIZE = {"gauge": 4.0, "width": 3.0, "clamp": 0.5}
QUICK_SIZE = {"gauge": 2.0, "width": 1.5, "clamp": 0.5}
# Strips larger than this many nodes are shrunk to it, the same shape: quick for CI; full so that
# a dense woven's swatch fits the suite's 10 minutes (full size: a twill 4149 nodes, 795 s for
# three directions; a satin 10305 nodes). Knits stay at FULL_SIZE (~500 nodes).
MAX_NODES = {True: 600, False: 1500}
# Selvedges (join_selvedges): a piece end within this fraction of the repeat's smaller side of a
# long side is cut there (a course leaves the strip within its loops' reach of the cut line: wool
# jersey's warp strip, 0.10 of the repeat); a turn has at least this many edges.
SELVEDGE_REACH = 0.25
SELVEDGE_MIN_EDGES = 4
# A frame's third axis in its own coordinates (d3 = R e3: the yarn's tangent).
E3 = np.array([0.0, 0.0, 1.0])
# Pieces shorter than this fraction of the repeat's smaller side are dropped (clipped fragments).
MIN_PIECE_FRACTION = 0.5
# A node within this fraction of an edge length outside the jaw line still counts as clamped
# (round-off of the unrolled positions).
CLAMP_SLACK = 1e-9
# Newton iterations per strain; a solve that needs more is reported as not converged. The cotton
# twill's warp strip (1819 nodes, the presets' largest) converges at 2 / 5 / 10 % in 345 / 694 /
# 1835 iterations, ~60 ms each on one core (session 29): 800 lets its 5 % converge (45 s) and keeps
# a solve that will not within about a minute.
MAX_ITERATIONS = 800
# The load step of a quick run (``stretch_repeat(quick=True)``, ``yarnfit validate --quick``): one
# step per strain level (2, 3 and 5 %), as a smoke run affords; its strips are small anyway.
QUICK_FRICTION_STRAIN_STEP = 0.05
# Tolerances of the swatch solves: the solver's defaults except the force and torque imbalance,
# which at 1e-8 sat below the round-off floor of a cut swatch (many contacts, ~1e4 nodes); 1e-6 of
# the force scale is still six digits on the reaction.
SWATCH_OPTIONS = dict(force_tolerance=1e-6, torque_tolerance=1e-6, energy_tolerance=1e-10,
                      penetration_tolerance=1e-4, max_iterations=MAX_ITERATIONS)


def cut_swatch(model: RodModel, position: np.ndarray, material: RodSection | RodMaterial, *, direction: str = "weft",
               gauge: float, width: float, clamp: float, selvedge: bool = False) -> Swatch:
    """Cut a strip from the flat periodic ``model`` at ``position`` (its relaxed rest state, frames
    its rest frames): ``gauge`` × ``width`` between the jaws plus a ``clamp`` band at each end (m),
    pulled along ``direction`` (a key of :data:`PULL_DIRECTIONS`: the suite's directions or the
    other bias, −45°); with ``selvedge``, the yarns running across it are joined at its long sides
    (:func:`join_selvedges`). See the module docstring."""
    if direction not in PULL_DIRECTIONS:
        raise ValueError(f"direction must be one of {', '.join(PULL_DIRECTIONS)}, got {direction!r}")
    for value, what in ((gauge, "gauge"), (width, "width"), (clamp, "clamp")):
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{what} must be a positive length in m, got {value!r}")
    angle = math.radians(PULL_DIRECTIONS[direction])
    c, s = math.cos(angle), math.sin(angle)
    # World (x along the pull u, y across v) from material coordinates, about the repeat's centre.
    rotation = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    length = gauge + 2.0 * clamp
    smaller = min(np.linalg.norm(model.lattice[0]), np.linalg.norm(model.lattice[1]))  # repeat side
    rods = []
    pieces = cut_rectangle(model, position, rotation, length, width, MIN_PIECE_FRACTION * smaller)
    if selvedge:
        pieces = join_selvedges(pieces, width, gauge, SELVEDGE_REACH * smaller)
    for piece in pieces:
        x = piece.points[:, 0]
        slack = CLAMP_SLACK * length
        pinned = np.flatnonzero((x <= -gauge / 2 + slack) | (x >= gauge / 2 - slack))
        n = len(x)
        both = np.flatnonzero(np.isin(np.arange(n - 1), pinned) & np.isin(np.arange(1, n), pinned))
        rods.append(Rod(points=piece.points, radius=piece.radius, material=material, frames=piece.frames,
                        rest_lengths=piece.rest_lengths, pinned_nodes=pinned.tolist(), pinned_frames=both.tolist(),
                        name=f"piece {len(rods)}"))
    if not rods:
        raise ValueError("the strip contains no yarn")
    built = RodModel.from_rods(rods)
    x = built.node_rest_position[:, 0]
    moving = np.flatnonzero(built.node_pinned & (x > 0))
    fixed = np.flatnonzero(built.node_pinned & (x < 0))
    if moving.size == 0 or fixed.size == 0:
        raise ValueError("no yarn reaches into both jaws: the strip transmits no force")
    return Swatch(model=built, position=np.array(built.node_rest_position), moving=moving, fixed=fixed,
                  length=length, width=width, gauge=gauge, clamp=clamp,
                  radius=float(built.edge_radius.max()), direction=direction, angle_deg=PULL_DIRECTIONS[direction])


def join_selvedges(pieces: Sequence[YarnPiece], width: float, gauge: float, reach: float) -> list[YarnPiece]:
    """Flat-knit selvedges for a strip pulled across its yarns (a knit's warp strip): the pieces
    that run from one long side to the other (ends within ``reach`` of each side, m) and lie
    between the jaws, in order along the pull, joined end to end, course k to course k + 1 at the
    +y side for even k and at the −y side for odd k, by a half circle outside the strip
    (:func:`_turn`); loop fragments lying wholly within ``reach`` of a side between the jaws (legs
    of the outermost loops, cut off their courses) are dropped, the turns taking their place. The
    strip's courses become one serpentine yarn, as a flat knitting machine makes it, so that a
    course can draw yarn only from its neighbours, not from a free end (a frictionless cut edge
    feeds its loops from there, which is not the fabric: session 28, wool jersey). Other pieces
    are returned as they are."""
    side = 0.5 * width - reach

    def between_jaws(piece: YarnPiece) -> bool:
        return bool(np.all(np.abs(piece.points[[0, -1], 0]) < 0.5 * gauge))

    def across(piece: YarnPiece) -> bool:
        ends = piece.points[[0, -1], 1]
        return between_jaws(piece) and bool(np.all(np.abs(ends) >= side) and ends[0] * ends[1] < 0.0)

    def fragment(piece: YarnPiece) -> bool:
        return between_jaws(piece) and bool(np.all(np.abs(piece.points[:, 1]) >= side))

    courses = sorted((p for p in pieces if across(p)), key=lambda p: float(p.points[:, 0].mean()))
    if len(courses) < 2:
        return list(pieces)
    edge = float(np.median(np.concatenate([p.rest_lengths for p in courses])))
    joined = None
    for k, course in enumerate(courses):
        # Course k runs towards the side it is joined to course k + 1 at: +y for even k.
        towards = 1.0 if k % 2 == 0 else -1.0
        if (course.points[-1, 1] - course.points[0, 1]) * towards < 0.0:
            course = _reversed(course)
        if joined is None:
            joined = course
            continue
        turn = _turn(joined, course, -towards, edge)
        joined = YarnPiece(np.concatenate([joined.points, turn.points[1:-1], course.points]),
                           np.concatenate([joined.rest_lengths, turn.rest_lengths, course.rest_lengths]),
                           np.concatenate([joined.frames, turn.frames, course.frames]), joined.radius)
    return [p for p in pieces if not (across(p) or fragment(p))] + [joined]


def _reversed(piece: YarnPiece) -> YarnPiece:
    """The piece run the other way: each frame turned by π about its own d1, so that d3 follows
    the new direction (d2 flips with it)."""
    flipped = as_rotations(piece.frames[::-1]) * Rotation.from_rotvec([math.pi, 0.0, 0.0])
    return YarnPiece(piece.points[::-1].copy(), piece.rest_lengths[::-1].copy(), as_frames(flipped), piece.radius)


def _turn(before: YarnPiece, after: YarnPiece, outward: float, edge: float) -> YarnPiece:
    """The half circle from ``before``'s last node to ``after``'s first, bulging ``outward`` (±y)
    beyond the strip, its nodes about ``edge`` apart: its rest shape is its shape (a turn at rest
    carries no force). Its frames are transported without twist from ``before``'s last edge, and
    the twist that leaves against ``after``'s first frame is spread evenly over its edges."""
    start, end = before.points[-1], after.points[0]
    chord = end - start
    radius = 0.5 * float(np.linalg.norm(chord))
    if not radius > before.radius:
        raise ValueError(f"selvedge: consecutive courses end {2 * radius:.3g} m apart, closer than a yarn diameter")
    along = chord / (2.0 * radius)
    out = np.array([0.0, outward, 0.0]) - outward * along[1] * along
    out /= np.linalg.norm(out)
    n = max(SELVEDGE_MIN_EDGES, int(math.ceil(math.pi * radius / edge)))
    phi = np.linspace(0.0, math.pi, n + 1)
    points = 0.5 * (start + end) + radius * (-np.cos(phi)[:, None] * along + np.sin(phi)[:, None] * out)
    points[0], points[-1] = start, end
    segments = np.diff(points, axis=0)
    lengths = np.linalg.norm(segments, axis=1)
    tangents = segments / lengths[:, None]
    frame = as_rotations(before.frames[-1:])[0]
    frames = []
    for t in tangents:
        frame = as_rotations(quaternion_between(frame.apply(E3), t)[None])[0] * frame
        frames.append(frame)
    first_after = as_rotations(after.frames[:1])[0]
    tangent_after = first_after.apply(E3)
    arrived = as_rotations(quaternion_between(frame.apply(E3), tangent_after)[None])[0] * frame
    # The turn left between them is about after's first tangent: its signed angle.
    left = (first_after * arrived.inv()).as_rotvec()
    twist = float(left @ tangent_after)
    spread = [Rotation.from_rotvec(twist * (i + 1) / (n + 1) * t) * f for i, (t, f) in enumerate(zip(tangents, frames))]
    return YarnPiece(points, lengths, as_frames(Rotation.concatenate(spread)), before.radius)


def _stretched_guess(swatch: Swatch, state: RodState, strain: float, previous: float) -> RodState:
    """The warm start of a pull to ``strain`` from ``state``, the equilibrium at ``previous``: its
    free nodes stretched affinely between the jaws, the moving jaw's nodes exactly at their new
    place (a rigid translation, frames unchanged)."""
    model = swatch.model
    jaw0 = -swatch.gauge / 2
    x = state.node_position.copy()
    free = ~model.node_pinned
    x[free, 0] = jaw0 + (x[free, 0] - jaw0) * (1.0 + strain) / (1.0 + previous)
    x[swatch.moving, 0] = swatch.position[swatch.moving, 0] + strain * swatch.gauge
    return replace(state, node_position=x)


def stretch_swatch(swatch: Swatch, strains: Sequence[float] = STRAINS, *,
                   options: QuasiStaticOptions | None = None, width_band: float | None = None,
                   on_step: Callable[[int, float, np.ndarray, dict], None] | None = None,
                   progress: Callable[[str], None] | None = None, friction: float = 0.0,
                   strain_step: float = FRICTION_STRAIN_STEP,
                   step_progress: Callable[[str], None] | None = None,
                   checkpoint: str | os.PathLike | None = None) -> dict:
    """Pull ``swatch`` to each of ``strains`` (ascending, > 0) in turn, each a converged solve
    warm-started from the previous one. ``on_step(k, strain, position, point)`` is called after
    each solve (k = 0 for the unstrained state, then 1, 2, ...). ``width_band`` (m, default a
    quarter of the strip width) is the half-length of the mid-length slab the width is measured
    in (:func:`~yarnfit.validate.strip.extent_width`). ``friction`` μ > 0: Coulomb friction at the
    yarn contacts, each strain reached from the last in equal lagged frictional load steps of at
    most ``strain_step`` (:data:`FRICTION_STRAIN_STEP`; :func:`yarnfit.engine.lagged.lagged_solve`),
    a step that does not converge or settle taken in halves
    (:func:`yarnfit.engine.lagged.in_halves`; a point's ``load_steps`` says how many steps it took,
    the halves counted, its ``iterations``, ``friction_passes`` and ``seconds`` count
    all of them, ``slowest_step_seconds`` is the longest one's time, and it is converged only if
    every step converged and its normal forces settled). ``progress`` gets a line per strain,
    ``step_progress`` one per load step of a strain reached in several (a large strip's level takes
    hours). ``checkpoint``: a file the pull writes where it stands after every load step
    (:class:`~yarnfit.validate.checkpoint.PullCheckpoint`); if it exists, the pull resumes from it
    (:class:`~yarnfit.validate.checkpoint.CheckpointError` if it is another pull's), calling
    ``on_step`` again for the levels it had finished. Returns a JSON-able dict (see the module docstring)."""
    strains = [float(e) for e in strains]
    if not strains or any(not (math.isfinite(e) and e > 0) for e in strains) or strains != sorted(strains):
        raise ValueError(f"strains must be positive and ascending, got {strains!r}")
    if not (math.isfinite(friction) and friction >= 0.0):
        raise ValueError(f"friction must be a finite coefficient >= 0, got {friction!r}")
    strain_step = positive_number(strain_step, "strain_step")
    model = swatch.model
    options = options or QuasiStaticOptions(**SWATCH_OPTIONS)
    solver = QuasiStaticSolver(model, options)
    band = 0.25 * swatch.width if width_band is None else float(width_band)
    rest = swatch.position
    width0 = mid_width(swatch, rest)
    extent0 = extent_width(swatch, rest, band)
    fingerprint = None if checkpoint is None else pull_fingerprint(swatch, strains, options, band, friction,
                                                                   strain_step)
    resumed = PullCheckpoint.read(checkpoint, fingerprint) if checkpoint is not None and Path(checkpoint).exists() \
        else None
    state = RodState.from_model(model)
    points = [{"strain": 0.0, "force_n_per_m": 0.0, "fixed_force_n_per_m": 0.0, "rod_force_n_per_m": 0.0,
               "cut_force_n_per_m": 0.0, "middle_force_n_per_m": 0.0, "middle_force_range_n_per_m": [0.0, 0.0],
               "quarter_forces_n_per_m": [0.0] * 4,
               "compression_ratio": 1.0, "middle_compression_ratio": 1.0, "mid_strain": 0.0, "extent_ratio": 1.0,
               "width_m": width0,
               "edge_draw_in_m": 0.0 if len(free_side_ends(swatch)) else None, "converged": True, "iterations": 0,
               "seconds": 0.0, "residual": None}]
    previous, contacts, level_positions = 0.0, None, []
    if resumed is not None:
        points, previous, state, contacts = resumed.points, resumed.previous, resumed.state, resumed.contacts
        level_positions = list(resumed.level_positions)
        if progress is not None:
            where = (f"load step {resumed.step} towards {100 * strains[resumed.level - 1]:g} %"
                     if resumed.level <= len(strains) and resumed.step > 0 else f"{100 * previous:g} %")
            progress(f"{swatch.direction}: resumed from {checkpoint} after {where}")
    if on_step is not None:
        on_step(0, 0.0, rest, points[0])
        for k, position in enumerate(level_positions, start=1):
            on_step(k, strains[k - 1], position, points[k])

    def take(begin, low, high):
        return _swatch_step(swatch, solver, begin, low, high, friction)

    def save(level: int, step: int, totals: LevelTotals) -> None:
        """Where the pull stands, in the checkpoint file (if any)."""
        if checkpoint is not None:
            finished = np.array(level_positions).reshape(-1, model.n_nodes, 3)
            PullCheckpoint(fingerprint, level, step, previous, points, finished, totals, state, contacts).write(checkpoint)

    for k, strain in enumerate(strains, start=1):
        if k <= len(level_positions):
            continue  # finished before the pull was resumed
        steps = load_step_count(previous, strain, strain_step) if friction > 0.0 else 1
        totals, done = LevelTotals(), 0
        if resumed is not None and k == resumed.level and resumed.step > 0:  # within the level
            totals, done = resumed.totals, resumed.step
        start = time.perf_counter() - totals.seconds
        for j in range(done + 1, steps + 1):
            step_start = time.perf_counter()
            low = previous + (strain - previous) * (j - 1) / steps
            target = strain if j == steps else previous + (strain - previous) * j / steps
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", ConvergenceWarning)
                # A frictional step that does not converge or settle is taken in halves (a
                # frictionless strain is one solve, with no path to divide).
                path, tried = in_halves(take, _SwatchStep.accepted, _SwatchStep.end, (state, contacts), low, target,
                                        STEP_HALVINGS if friction > 0.0 else 0)
            step_iterations = sum(step.iterations for step in tried)
            step_passes = sum(step.passes for step in tried)
            totals.iterations += step_iterations
            totals.passes += step_passes
            step_converged = True
            for step in path:
                result, lagged = step.result, step.lagged
                accepted = step.accepted()
                step_converged &= accepted
                state, contacts = result.state, result.contacts
                # The middle's reading after every step; the level's point is its last step's.
                cut = cut_forces(swatch, state, result.contacts, None if lagged is None else lagged.anchors)
                width = mid_width(swatch, state.node_position)
                totals.readings.append({
                    "strain": step.strain,
                    "mid_strain": finite_or_none(mid_strain(swatch, state.node_position)),
                    "middle_force_n_per_m": float(cut.middle.mean()) / (0.5 * swatch.width),
                    "middle_compression_ratio": finite_or_none(middle_compression(swatch, state.node_position)),
                    "compression_ratio": width / width0,
                    "converged": accepted,
                })
            totals.converged &= step_converged
            step_seconds = time.perf_counter() - step_start
            totals.slowest = max(totals.slowest, step_seconds)
            if j < steps:  # the level's last step is saved with its point
                totals.seconds = time.perf_counter() - start
                save(k, j, totals)
            if step_progress is not None and steps > 1:
                reading = totals.readings[-1]
                step_progress(f"{swatch.direction} {100 * target:.4g} % (load step {j} of {steps} towards "
                              f"{100 * strain:g} %): middle half {reading['middle_force_n_per_m']:.5g} N/m at "
                              f"{_strain_text(reading['mid_strain'])}, "
                              f"{'converged' if step_converged else 'NOT converged'}, {step_iterations} iterations, "
                              f"{step_passes} friction passes, {len(tried)} step(s) tried ({step_seconds:.0f} s)")
        middle = totals.readings[-1]
        _, rod_gradient, _ = energy_gradient(model, state)
        pull = float(result.reaction_force[swatch.moving, 0].sum())
        back = float(result.reaction_force[swatch.fixed, 0].sum())
        rod_pull = float(rod_gradient[swatch.moving, 0].sum())
        r = result.residual
        point = {
            "strain": strain,
            "force_n_per_m": pull / swatch.width,
            "fixed_force_n_per_m": -back / swatch.width,
            "rod_force_n_per_m": rod_pull / swatch.width,
            "contact_share": 0.0 if pull == 0 else 1.0 - rod_pull / pull,
            "cut_force_n_per_m": float(cut.whole.mean()) / swatch.width,
            "middle_force_n_per_m": middle["middle_force_n_per_m"],
            "middle_force_range_n_per_m": [float(cut.middle.min()) / (0.5 * swatch.width),
                                           float(cut.middle.max()) / (0.5 * swatch.width)],
            "quarter_forces_n_per_m": (cut.quarters.mean(axis=0) / (0.25 * swatch.width)).tolist(),
            "compression_ratio": middle["compression_ratio"],
            "middle_compression_ratio": middle["middle_compression_ratio"],
            "mid_strain": middle["mid_strain"],
            "extent_ratio": extent_width(swatch, state.node_position, band) / extent0,
            "width_m": width,
            "edge_draw_in_m": finite_or_none(edge_draw_in(swatch, state.node_position, width / width0)),
            "converged": totals.converged,
            "iterations": int(totals.iterations),
            "load_steps": len(totals.readings),
            "slowest_step_seconds": totals.slowest,
            "friction_passes": None if lagged is None else totals.passes,
            "friction_change": None if lagged is None else lagged.force_change,
            "seconds": time.perf_counter() - start,
            "residual": {"force": float(r.force), "torque": float(r.torque), "energy_change": float(r.energy_change),
                         "penetration": float(r.penetration), "force_floor": float(r.force_floor),
                         "torque_floor": float(r.torque_floor)},
            "energy_j": result.energy.internal,
            "contact_pairs": int(len(result.contact_pairs)),
            "steps": totals.readings,
        }
        points.append(point)
        level_positions.append(state.node_position.copy())
        previous = strain
        save(k + 1, 0, LevelTotals())
        if progress is not None:
            stepped = "" if lagged is None else \
                f" over {point['load_steps']} load steps and {point['friction_passes']} friction passes"
            progress(f"{swatch.direction} {100 * strain:g} %: {point['force_n_per_m']:.5g} N/m (middle half "
                     f"{point['middle_force_n_per_m']:.5g} N/m at {_strain_text(point['mid_strain'])}, width ratio "
                     f"{_ratio_text(point['middle_compression_ratio'])}), compression "
                     f"{point['compression_ratio']:.4f}, {'converged' if point['converged'] else 'NOT converged'} "
                     f"in {point['iterations']} iterations"
                     f"{stepped} "
                     f"({point['seconds']:.1f} s; {r})")
        if on_step is not None:
            on_step(k, strain, state.node_position, point)
    return swatch_curve(swatch, points)


@dataclass(frozen=True)
class _SwatchStep:
    """One load step of a pull (:func:`stretch_swatch`): the strain it reached, its last solve's
    result, its lagged solve (``None`` without friction)."""

    strain: float
    result: QuasiStaticResult
    lagged: LaggedSolve | None

    def accepted(self) -> bool:
        """Converged, and with friction its normal forces settled."""
        return bool(self.result.converged) and (self.lagged is None or bool(self.lagged.settled))

    def end(self) -> tuple[RodState, ContactSet]:
        """Where the next step starts: the state reached and its contacts."""
        return self.result.state, self.result.contacts

    @property
    def iterations(self) -> int:
        return self.result.iterations if self.lagged is None else self.lagged.iterations

    @property
    def passes(self) -> int:
        return 0 if self.lagged is None else self.lagged.passes


def _swatch_step(swatch: Swatch, solver: QuasiStaticSolver, start: tuple[RodState, ContactSet | None], low: float,
                 high: float, friction: float) -> _SwatchStep:
    """The pull's load step from ``start`` (its state and contacts at the strain ``low``; no
    contacts at the unloaded rest) to ``high``: one lagged frictional solve with friction μ
    ``friction`` anchored at the start (:func:`~yarnfit.engine.lagged.lagged_solve`), one solve
    without."""
    state, contacts = start
    guess = _stretched_guess(swatch, state, high, low)
    if friction > 0.0:
        lagged = lagged_solve(solver, guess, state.node_position, friction,
                              anchors_from=None if contacts is None else (state.node_position, contacts))
        return _SwatchStep(high, lagged.result, lagged)
    # One solve per strain, and a large one: it keeps the penalties the last strain stiffened
    # (ContactSet.with_base_penalties says why frictional steps do not).
    return _SwatchStep(high, solver.solve(guess, contacts=contacts), None)


def swatch_curve(swatch: Swatch, points: Sequence[dict]) -> dict:
    """The JSON-able curve :func:`stretch_swatch` returns, from ``swatch`` and its ``points`` (the
    rest point first, then one per strain reached): also the curve so far of a pull still running
    (a convergence study writes it after every strain, so a run stopped part way keeps its levels)."""
    points = list(points)
    model = swatch.model
    return {
        "direction": swatch.direction,
        "angle_deg": swatch.angle_deg,
        "gauge_m": swatch.gauge,
        "width_m": swatch.width,
        "clamp_m": swatch.clamp,
        "nodes": int(model.n_nodes),
        "pieces": int(model.n_rods),
        "pinned_nodes": int(model.node_pinned.sum()),
        "strain": [p["strain"] for p in points],
        "force_n_per_m": [p["force_n_per_m"] for p in points],
        "compression_ratio": [p["compression_ratio"] for p in points],
        "converged": all(p["converged"] for p in points),
        "points": points,
        "seconds": float(sum(p["seconds"] for p in points)),
    }


# A strain the strip's middle did not reach is read off its curve's last stretch extended by at
# most this fraction of the strain reached, and not further: a woven's middle strains a little
# less than its jaws' travel (the twill's 8 × 6 warp strip 1.98 % at 2 %), and a power law over
# that little is as good as its fit of the stretch before it.
UNIFORM_EXTRAPOLATION_RTOL = 0.05


@dataclass(frozen=True)
class UniformReading:
    """A strip's uniform part read at a strain its middle reached (:func:`read_uniform`).

    Attributes:
        strain: the middle's strain read at (as asked).
        force_n_per_m: the middle half's pull per width there (N/m).
        compression_ratio: the middle half's width ratio there.
        converged: whether both states it was read between converged.
        source: ``"steps"`` (read between load steps) or ``"levels"`` (between the reported
            strains: a curve written before its steps were kept, or a step without a reading).
        extrapolated: beyond the last strain the middle reached (by at most
            :data:`UNIFORM_EXTRAPOLATION_RTOL` of it).
    """

    strain: float
    force_n_per_m: float
    compression_ratio: float
    converged: bool
    source: str
    extrapolated: bool


def uniform_curve(curve: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, str]:
    """The strip's uniform part along its pull, from :func:`stretch_swatch`'s ``curve``: the
    middle's strain, pull per width (N/m), width ratio (the middle half's, or the whole width's at
    mid-length where a mark held no node) and converged flag ``(n,)`` each, from rest through every
    load step in order, and the source (``"steps"``, or ``"levels"`` when any level kept no
    steps). States without a middle reading (an empty mark) are left out."""
    states, source = [(0.0, 0.0, 1.0, True)], "steps"
    for point in curve["points"][1:]:
        steps = point.get("steps")
        if not steps:
            steps, source = [point], "levels"
        for step in steps:
            strain, force = step.get("mid_strain"), step.get("middle_force_n_per_m")
            width = step.get("middle_compression_ratio")
            width = step.get("compression_ratio") if width is None else width
            if strain is None or force is None or width is None:
                continue
            states.append((float(strain), float(force), float(width), bool(step["converged"])))
    strain, force, width, converged = (np.array(column) for column in zip(*states))
    return strain, force, width, converged.astype(bool), source


def read_uniform(curve: dict, strains: Sequence[float]) -> list[UniformReading | None]:
    """The strip's uniform part at each of ``strains`` (its middle's, > 0), as a tensile tester
    with an extensometer reads a force at a strain off its record: between the two states of
    :func:`uniform_curve` the middle's strain lies between (the first such pair), the pull on the
    power law through them (exact for a pull that grows as a power of the strain; below the first
    state, the power law of the first two, through the origin), the width ratio linear in the
    strain. ``None`` for a strain the middle did not reach (beyond
    :data:`UNIFORM_EXTRAPOLATION_RTOL`) or a curve with no middle reading."""
    return read_curve(*uniform_curve(curve), strains)


def read_curve(m: np.ndarray, f: np.ndarray, c: np.ndarray, ok: np.ndarray, source: str,
               strains: Sequence[float]) -> list[UniformReading | None]:
    """:func:`read_uniform` on a uniform part given as arrays (the middle's strain, pull per width
    (N/m), width ratio and converged flag ``(n,)`` each, rest first, in load order, and their
    ``source``): a shell strip's (:mod:`yarnfit.validate.shell_strip`) is read as a yarn strip's."""
    readings: list[UniformReading | None] = []
    for target in strains:
        target = float(target)
        if not (math.isfinite(target) and target > 0.0):
            raise ValueError(f"strains must be positive, got {target!r}")
        if len(m) < 2:
            readings.append(None)
            continue
        extrapolated = False
        inside = np.nonzero((m[:-1] <= target) & (target <= m[1:]))[0]
        if len(inside):
            i = int(inside[0])
        elif target > m.max() and target <= (1.0 + UNIFORM_EXTRAPOLATION_RTOL) * m[-1] and m[-1] == m.max():
            i, extrapolated = len(m) - 2, True
        else:
            readings.append(None)
            continue
        along = 0.0 if m[i + 1] == m[i] else (target - m[i]) / (m[i + 1] - m[i])
        a, b = (1, 2) if i == 0 and len(m) > 2 else (i, i + 1)
        if m[a] > 0.0 and m[b] > m[a] and f[a] > 0.0 and f[b] > 0.0:
            force = f[a] * (target / m[a]) ** (math.log(f[b] / f[a]) / math.log(m[b] / m[a]))
        else:  # the origin and one state, or a pull that is not positive: linear
            force = f[i] + (f[i + 1] - f[i]) * along
        width = c[i] + (c[i + 1] - c[i]) * along
        readings.append(UniformReading(target, float(force), float(width), bool(ok[i] and ok[i + 1]), source,
                                       extrapolated))
    return readings


def _strain_text(strain: float | None) -> str:
    return "an unmarked strain" if strain is None else f"{100 * strain:.3g} %"


def _ratio_text(ratio: float | None) -> str:
    return "unmarked" if ratio is None else f"{ratio:.4f}"


def stretch_repeat(model: RodModel, position: np.ndarray, material: RodSection | RodMaterial, *, name: str = "swatch",
                   directions: Sequence[str] = ("weft", "warp"), strains: Sequence[float] = STRAINS,
                   size: dict | None = None, quick: bool = False, recording_path=None,
                   progress: Callable[[str], None] | None = None, options: QuasiStaticOptions | None = None,
                   friction: float = 0.0) -> dict:
    """The stretch test on strips cut from a relaxed flat periodic repeat (``model`` its rest model,
    ``position`` its rest positions, ``material`` the yarns'). ``size``: gauge, width and clamp in
    repeats of the larger repeat side (default :data:`FULL_SIZE`, or :data:`QUICK_SIZE` with
    ``quick``), or in metres with keys ``gauge_m``, ``width_m``, ``clamp_m``; ``friction`` μ at the
    yarn contacts (:func:`stretch_swatch`; in load steps of :data:`FRICTION_STRAIN_STEP`, or
    :data:`QUICK_FRICTION_STRAIN_STEP` with ``quick``). Returns a JSON-able dict: per direction
    the curves of :func:`stretch_swatch`."""
    start = time.perf_counter()
    repeat = max(np.linalg.norm(model.lattice[0]), np.linalg.norm(model.lattice[1]))
    size = dict(size or (QUICK_SIZE if quick else FULL_SIZE))
    if {"gauge_m", "width_m", "clamp_m"} <= size.keys():
        dims = {k: float(size[f"{k}_m"]) for k in ("gauge", "width", "clamp")}
    else:
        dims = {k: float(size[k]) * repeat for k in ("gauge", "width", "clamp")}
    recording = None if recording_path is None else SwatchRecording(name, recording_path)
    out = {"name": name, "strains": list(strains), "directions": {}, "friction": float(friction)}
    step = 0
    try:
        for direction in directions:
            swatch = cut_swatch(model, position, material, direction=direction, **dims)
            if swatch.model.n_nodes > MAX_NODES[quick]:
                # A dense weave's strip of QUICK_SIZE or FULL_SIZE repeats is thousands of nodes
                # (a satin's quick one 2900, 45 s per strain): shrink gauge and width to the budget.
                shrink = math.sqrt(MAX_NODES[quick] / swatch.model.n_nodes)
                swatch = cut_swatch(model, position, material, direction=direction, gauge=dims["gauge"] * shrink,
                                    width=dims["width"] * shrink, clamp=dims["clamp"])
            if progress is not None:
                progress(f"{direction}: {swatch.model.n_nodes} nodes in {swatch.model.n_rods} pieces, "
                         f"{1e3 * swatch.gauge:.3g} × {1e3 * swatch.width:.3g} mm between the jaws")
            base = step

            def on_step(k, strain, pos, point, swatch=swatch, base=base):
                if recording is not None:
                    recording.step(base + k, swatch, pos, strain, point)

            out["directions"][direction] = stretch_swatch(
                swatch, strains, options=options, on_step=on_step, progress=progress, friction=friction,
                strain_step=QUICK_FRICTION_STRAIN_STEP if quick else FRICTION_STRAIN_STEP)
            step = base + len(strains) + 1
        out["seconds"] = time.perf_counter() - start
        if recording is not None:
            recording.finish(out)
    finally:
        if recording is not None:
            recording.close()
    return out


@dataclass(frozen=True)
class YarnResult(SceneResult):
    """The yarn-level stretch test of a material: the swatch's ``name`` and the ``strains`` pulled
    to, the curve per direction (:func:`stretch_swatch`'s dict), wall ``seconds`` of the pulls, the
    material's name, ``quick``, the relaxation it was cut from (converged, iterations, seconds,
    radius_m, repeat_size_m), the recording's path (or None) and the friction coefficient at the
    yarn contacts (0: frictionless)."""

    name: str
    strains: list[float]
    directions: dict
    seconds: float
    material: str
    quick: bool
    relaxation: dict
    recording: str | None
    friction: float = 0.0


def yarn_directions(quick: bool) -> tuple[str, ...]:
    """The directions the yarn scene pulls by default: weft and warp, and bias unless ``quick``."""
    return ("weft", "warp") if quick else ("weft", "warp", "bias")


def merge_yarn_summaries(parts: Sequence[dict]) -> dict:
    """One yarn scene's summary from the summaries of runs of one direction each
    (:func:`run_yarn` with ``directions=(d,)``, as the suite runs them side by side): the curves of
    every part in order, the pulls' ``seconds`` summed, and ``recordings``, every part's recording,
    in place of ``recording``; the rest (material, strains, relaxation, friction) is the first
    part's, which every part shares."""
    if not parts:
        raise ValueError("no yarn scene parts to merge")
    merged = {key: value for key, value in parts[0].items() if key != "recording"}
    merged["directions"] = {direction: curve for part in parts for direction, curve in part["directions"].items()}
    merged["seconds"] = float(sum(part["seconds"] for part in parts))
    merged["recordings"] = [part["recording"] for part in parts if part.get("recording") is not None]
    return merged


def run_yarn(material, *, quick: bool = False, recording_path=None, progress: Callable[[str], None] | None = None,
             directions: Sequence[str] | None = None, size: dict | None = None, friction: bool = True) -> YarnResult:
    """The yarn-level stretch test of a material file (path or its decoded dict): take the relaxed
    repeat the file keeps (a file without one has the fabric of its ``inputs`` relaxed again, with a
    note through ``progress``), cut strips along weft and warp (and bias unless ``quick``) and pull
    each to 2, 5 and 10 %, with the fibre's friction at the yarn contacts (``friction=False``:
    frictionless). ``recording_path`` defaults to
    ``logs/<material>/yarn.rrd`` (``False``: no recording). ``size`` overrides the strip size
    (see :func:`stretch_repeat`)."""
    file = MaterialFile.read(material)
    where, fabric = file.where, file.fabric()
    start = time.perf_counter()
    relaxed = file.relaxed_or_relaxed_again(progress)
    relax_seconds = time.perf_counter() - start
    if not relaxed.valid:
        raise ValueError(f"{where}: the relaxation of {fabric.name!r} is not usable ({relaxed.residual})")
    if recording_path is None:
        recording_path = Path("logs") / fabric.name / "yarn.rrd"
    elif recording_path is False:
        recording_path = None
    directions = directions or yarn_directions(quick)
    coefficient = float(fabric.fiber.friction) if friction else 0.0
    out = stretch_repeat(relaxed.model, relaxed.state.node_position, relaxed.yarn.section(), name=fabric.name,
                         directions=directions, size=size, quick=quick, recording_path=recording_path,
                         progress=progress, friction=coefficient)
    relaxation = {"converged": relaxed.converged, "iterations": relaxed.iterations, "seconds": relax_seconds,
                  "radius_m": relaxed.radius, "repeat_size_m": [float(v) for v in relaxed.repeat_size]}
    return YarnResult(name=out["name"], strains=out["strains"], directions=out["directions"], seconds=out["seconds"],
                      material=fabric.name, quick=bool(quick), relaxation=relaxation,
                      recording=None if recording_path is None else str(recording_path), friction=coefficient)


# -- recording ---------------------------------------------------------------------------------


STRAIN_TIMELINE = "strain"


class SwatchRecording(Recording):
    """Writes a yarn-level stretch run to one ``.rrd`` file (see the module docstring)."""

    def __init__(self, name: str, path) -> None:
        super().__init__(name, path, blueprint(), "yarn")

    def step(self, k: int, swatch: Swatch, position: np.ndarray, strain: float, point: dict) -> None:
        rec = self.stream
        rec.set_time(STRAIN_TIMELINE, sequence=k)
        m = swatch.model
        strips = [position[m.rod_node_start[r]:m.rod_node_start[r + 1]] for r in range(m.n_rods)]
        colors = np.where(m.node_pinned[m.rod_node_start[:-1]][:, None], [[150, 150, 150]], [[60, 120, 220]])
        rec.log("yarn/swatch/yarns", rr.LineStrips3D(strips, radii=swatch.radius, colors=colors))
        rec.log(f"yarn/plots/force_{swatch.direction}", rr.Scalars(point["force_n_per_m"]))
        rec.log(f"yarn/plots/middle_force_{swatch.direction}", rr.Scalars(point["middle_force_n_per_m"]))
        rec.log(f"yarn/plots/compression_{swatch.direction}", rr.Scalars(point["compression_ratio"]))
        rec.log("yarn/plots/strain", rr.Scalars(strain))

    def finish(self, out: dict) -> None:
        self.log_markdown("yarn/summary", summary_markdown(out), static=True)


def blueprint():
    """The swatch in 3D on the left; force and compression plots and the summary on the right;
    time panel on the ``strain`` timeline."""
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(origin="yarn/swatch", name="swatch"),
            rrb.Vertical(
                rrb.TimeSeriesView(origin="yarn/plots", name="force (N/m) and compression ratio"),
                rrb.TextDocumentView(origin="yarn/summary", name="summary"),
            ),
            column_shares=[3, 2],
        ),
        *folded_panels(STRAIN_TIMELINE),
    )


def summary_markdown(out: dict) -> str:
    """Markdown table of a run: per direction and strain, force per width on the jaws and in the
    middle half (with the middle's strain), compression ratio of the whole width and of the middle
    half, edge draw-in, convergence, iterations, residuals and wall time."""
    rows = []
    for direction, curve in out["directions"].items():
        for p in curve["points"][1:]:
            res = p["residual"]["force"] if p["residual"] else float("nan")
            draw_in = p.get("edge_draw_in_m")
            middle = p.get("middle_force_n_per_m")
            rows.append((direction, f"{100 * p['strain']:g} %", f"{p['force_n_per_m']:.5g}",
                         "—" if middle is None else f"{middle:.5g}",
                         "—" if p.get("mid_strain") is None else f"{100 * p['mid_strain']:.3g} %",
                         f"{p['compression_ratio']:.4f}",
                         "—" if p.get("middle_compression_ratio") is None else f"{p['middle_compression_ratio']:.4f}",
                         "—" if draw_in is None else f"{1e6 * draw_in:.3g}",
                         "yes" if p["converged"] else "**no**", p["iterations"], f"{res:.2e}", f"{p['seconds']:.1f}"))
    header = ("direction", "strain", "force (N/m)", "middle half's force (N/m)", "middle's strain",
              "compression ratio", "middle half's compression ratio", "edge draw-in (µm)", "converged", "iterations",
              "force residual", "seconds")
    mu = out.get("friction", 0.0)
    lines = [f"# yarn-level stretch: {out.get('name', '')}", "",
             f"Friction at the yarn contacts: μ = {mu:g}." if mu else "Frictionless yarn contacts.", "",
             markdown_table(rows, header)]
    for direction, curve in out["directions"].items():
        lines.append(f"\n{direction}: {curve['nodes']} nodes, {curve['pieces']} yarn pieces, gauge "
                     f"{1e3 * curve['gauge_m']:.3g} mm × width {1e3 * curve['width_m']:.3g} mm")
    return "\n".join(lines) + "\n"
