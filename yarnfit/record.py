"""Rerun recordings of yarnfit runs.

Each recording writes one run to one ``.rrd`` file through its own ``rr.RecordingStream``
(application id ``"yarnfit"``, recording name = the run's name, the file's directory created) with
its viewer layout; the global recording is never touched. Open the file with ``rerun file.rrd``.

Relaxation
----------

A :class:`RelaxRecording` writes one relaxation run (phase 1, ``yarnfit.relax``).

Timeline ``iteration`` (sequence): one step per logged state, counting on across all relaxations
of the run (never reset). :meth:`RelaxRecording.start` logs each relaxation's unrelaxed pattern at
the next step, every Newton iteration (:meth:`RelaxRecording.__call__`) the next, and
:meth:`RelaxRecording.finish` the relaxed repeat at the step after the last. (Rerun adds its own
wall-clock timeline ``log_time`` to every temporal row.)

Entity paths (positions and radii in m, 3D in the fabric frame: x weft, y warp, z up):

- ``relax``: ``ViewCoordinates`` right-handed, z up (static).
- ``relax/repeat/yarns``: ``LineStrips3D``, one closed strip per yarn (the yarn's nodes, then its
  first node moved by the yarn's net tile offset), radius = yarn radius, one colour per yarn.
  Radii and colours are logged by ``start``, then only the strips change.
- ``relax/repeat/tile``: ``LineStrips3D``, outline of the repeat tile at z = 0 (by ``start``).
- ``relax/tiling/yarns``: ``LineStrips3D``, the same strips shifted by ``i a0 + j a1`` for
  i, j ∈ {−1, 0, 1} (``a0``, ``a1`` the lattice vectors; tile ``(i, j)`` holds strips
  ``3 (i + 1) + (j + 1)`` times the yarn count onwards): the centre tile in the yarn colours, its
  eight neighbours grey.
- ``relax/residual/force``, ``relax/residual/torque``, ``relax/residual/penetration``,
  ``relax/residual/energy_change``: ``Scalars``, the solver's residuals (dimensionless), logged
  as they are on a linear axis (rerun 0.41 time-series views have no log scale).
- ``relax/energy/potential``: ``Scalars``, total potential energy at each iteration (J).
- ``relax/energy/stretch``, ``relax/energy/shear``, ``relax/energy/bend``, ``relax/energy/twist``,
  ``relax/energy/external``, ``relax/energy/total``: ``Scalars``, energy terms at equilibrium (J),
  logged once by ``finish``.
- ``relax/summary``: ``TextDocument`` (markdown), the relaxed repeat in numbers (by ``finish``).

Typical use (``relax_pattern`` knows nothing of recordings, so the caller announces each
relaxation with :meth:`RelaxRecording.start`)::

    recording = RelaxRecording(fabric.name, "logs/relax.rrd")
    pattern = fabric.pattern()
    recording.start(pattern)
    result = relax_pattern(pattern, fabric.fiber, on_iteration=recording)
    recording.finish(result)

Shell fit
---------

A :class:`FitRecording` writes one shell fit run (phases 2 and 3, ``yarnfit.homogenize`` and
``yarnfit.fit``, driven by ``yarnfit.fabric_fit.fit_fabric``).

Timeline ``sample`` (sequence): sample k (its index in the design order of
``yarnfit.samples.sample_design``, 0-based, as in ``FabricFit.samples``) is logged at step k, in
whatever order the samples finish. The relaxed repeat, the fit curves and the summary are static.

Entity paths (positions and radii in m, 3D x weft, y warp, z up):

- ``fit``: ``ViewCoordinates`` right-handed, z up (static, when the recording opens).
- ``fit/relaxed/yarns``: ``LineStrips3D``, the relaxed repeat in its flat tile, one strip per yarn
  (``yarn_strips`` of tile (0, 0): a yarn crossing the tile border stays continuous), radius = yarn
  radius, one colour per yarn (static, by ``start``).
- ``fit/sample/yarns``: ``LineStrips3D``, the sample's equilibrium on its deformed mid-surface
  (origin at the repeat's centre) in 3 × 3 tiles: tile ``(i, j)``, i, j ∈ {−1, 0, 1}, i slowest,
  holds strips ``3 (i + 1) + (j + 1)`` times the yarn count onwards, ``yarn_strips`` of that tile
  of the model ``tile_repeat`` builds for the sample (each neighbour is the repeat carried on along
  the curved surface, not merely shifted); the centre tile in the yarn colours, its eight
  neighbours grey; radius = yarn radius (by ``sample``, at the sample's step).
- ``fit/sample/energy``: ``Scalars``, the sample's energy density Ū (J/m² of reference area; by
  ``sample``).
- ``fit/sample/info``: ``TextDocument`` (markdown), the sample's family, parameter, I, II (1/m), Ū,
  convergence, iterations and residuals (by ``sample``).
- ``fit/curves/<family>/yarn``: ``Points2D`` at (parameter, Ū) of the family's converged samples,
  Ū as the shell sees it (less the fitted rest energy and residual-stress terms,
  ``ShellFit.shell_energy``; static, by ``finish``).
- ``fit/curves/<family>/excluded``: ``Points2D`` in red at (parameter, Ū) of the family's samples
  that did not converge (excluded from the fit) with a finite Ū; only logged if there are any
  (static, by ``finish``).
- ``fit/curves/<family>/shell``: ``LineStrips2D``, the fitted shell's energy density
  ``W(Family.deformation(p))`` (for the uniaxial families ``W`` of
  ``ShellMaterial.uniaxial_tension``, the shell's own free width) over a dense range of p spanning the family's sampled
  parameters and 0, through every sampled parameter (static, by ``finish``).
- ``fit/summary``: ``TextDocument`` (markdown), the engineering constants in SI and user units (N/m,
  N·m and gf·cm²/cm for bending), R² and relative RMS per family, the bounds the fit reached (if
  any), model, thickness, sample counts and wall time per stage (static, by ``finish``).

``<family>`` is each of ``yarnfit.samples.FAMILIES`` with at least one sample. The curves' x is the
family's parameter (λ − 1 for the stretch families, I12 for shear, curvature in 1/m for the bend
families) and y is in J/m². Rerun 2D views keep x and y at equal scale with y pointing down, so
each curve entity also carries a static ``Transform3D`` scaling x by 1 / max |p| and y by
−1 / max W of its family: the plot fills a unit box, y up. The logged positions keep the units
above (hovering shows them).

Typical use, after the fit::

    recording = FitRecording(fabric.name, "logs/plain-fit.rrd")
    recording.start(fitted.relaxed)
    for index, result in enumerate(fitted.samples):
        recording.sample(index, fitted.relaxed, result)
    recording.finish(fitted)
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from .engine import Progress
from .engine.tiling import yarn_strips
from .homogenize import tile_repeat
from .patterns import YarnPattern
from .samples import FAMILIES, Family
from .shell import GF_CM2_PER_CM

APPLICATION_ID = "yarnfit"
TIMELINE = "iteration"
SAMPLE_TIMELINE = "sample"

# Yarn colours (RGB), cycled by yarn index; neighbour tiles are drawn in a neutral grey so the
# repeat itself stands out in the tiling.
YARN_COLORS = np.array([[31, 119, 180], [255, 127, 14], [44, 160, 44], [214, 39, 40], [148, 103, 189],
                        [140, 86, 75], [227, 119, 194], [188, 189, 34], [23, 190, 207]], dtype=np.uint8)
NEIGHBOUR_COLOR = np.array([150, 150, 150], dtype=np.uint8)
# Tile outline width relative to the yarn radius: thin enough not to hide the yarns.
TILE_LINE_RADIUS = 0.1

RESIDUALS = ("force", "torque", "penetration", "energy_change")
ENERGY_TERMS = ("stretch", "shear", "bend", "twist", "external", "total")

# Fit curves: yarn-level samples blue, samples left out red (the colour every plot uses for
# failures), the shell's curve black so it reads as the model, not as another sample.
SAMPLE_COLOR = YARN_COLORS[0]
EXCLUDED_COLOR = np.array([214, 39, 40], dtype=np.uint8)
SHELL_COLOR = np.array([30, 30, 30], dtype=np.uint8)
# Marker and line sizes in UI points: the curves are drawn through a scaling transform (see the
# module docstring), so sizes in scene units would change from family to family.
SAMPLE_POINT_SIZE = rr.Radius.ui_points(5.0)
SHELL_LINE_SIZE = rr.Radius.ui_points(1.5)
# Points of the shell curve's uniform grid (the sampled parameters are added to it): the curve is
# quadratic (bends) or piecewise quadratic (a ridge membrane's stretches) in p, smooth to the eye
# at this density.
CURVE_POINTS = 101
# A grid point this close to a sampled parameter (relative to the grid's span) is left out: far
# above float64 round-off, far below float32's 6e-8, which the recording stores.
CURVE_MERGE_REL = 1e-6

# Tile shifts (i, j) of the 3 × 3 tiling, i, j ∈ {−1, 0, 1}; the centre (0, 0) is entry 4.
_TILE_OFFSETS = tuple((i, j) for i in (-1, 0, 1) for j in (-1, 0, 1))
_TILES = np.array(_TILE_OFFSETS, dtype=np.float64)
_CENTRE = 4


def blueprint() -> rrb.Blueprint:
    """Viewer layout: the repeat and its 3 × 3 tiling in 3D on the left; residuals, energy and
    the summary on the right; the time panel open on the ``iteration`` timeline (not rerun's
    wall-clock ``log_time``), the blueprint and selection panels folded away."""
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Spatial3DView(origin="relax/repeat", name="repeat"),
                rrb.Spatial3DView(origin="relax/tiling", name="3 × 3 tiling"),
            ),
            rrb.Vertical(
                rrb.TimeSeriesView(origin="relax/residual", name="residuals (dimensionless)"),
                rrb.TimeSeriesView(origin="relax/energy", name="energy (J)"),
                rrb.TextDocumentView(origin="relax/summary", name="summary"),
            ),
            column_shares=[3, 2],
        ),
        *folded_panels(TIMELINE),
    )


def fit_blueprint() -> rrb.Blueprint:
    """Viewer layout of a fit: the relaxed repeat and the current sample's 3 × 3 tiling in 3D on
    the left; the sample energy, the sample's numbers and the summary in the middle; one 2D view
    per sample family with its fit curve on the right; the time panel on the ``sample`` timeline."""
    curves = [rrb.Spatial2DView(origin=f"fit/curves/{family}",
                                name=f"{family}: Ū (J/m²) over {family.label}") for family in FAMILIES]
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Spatial3DView(origin="fit/relaxed", name="relaxed repeat"),
                rrb.Spatial3DView(origin="fit/sample", name="sample (3 × 3 tiles)"),
                row_shares=[1, 2],
            ),
            rrb.Vertical(
                rrb.TimeSeriesView(origin="fit/sample/energy", name="sample energy Ū (J/m²)"),
                rrb.TextDocumentView(origin="fit/sample/info", name="sample"),
                rrb.TextDocumentView(origin="fit/summary", name="summary"),
            ),
            rrb.Grid(*curves, grid_columns=2, name="fit curves"),
            column_shares=[3, 2, 3],
        ),
        *folded_panels(SAMPLE_TIMELINE),
    )


def folded_panels(timeline: str) -> tuple:
    """The time panel open on ``timeline`` (not rerun's wall-clock ``log_time``), the blueprint
    and selection panels folded away."""
    return (rrb.BlueprintPanel(state="collapsed"), rrb.SelectionPanel(state="collapsed"),
            rrb.TimePanel(state="expanded", timeline=timeline))


class Recording:
    """One run's ``.rrd`` file: its own stream, the file sink, the recording name, the viewer
    layout and the view coordinates of the ``root`` entity (right-handed, z up)."""

    # Recordings not yet closed, so that an interrupt can discard them all (discard_open()).
    _open: "set[Recording]" = set()

    def __init__(self, name: str, path, layout: rrb.Blueprint, root: str) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        # Streamed to a hidden sibling and renamed on close: an interrupted run leaves no
        # half-written recording under the name the user asked for (discard() removes it).
        self.partial = self.partial_path(self.path)
        self.stream = rr.RecordingStream(APPLICATION_ID)
        # The file sink must be attached before anything is logged, or that data is lost.
        self.stream.save(self.partial)
        Recording._open.add(self)
        self.stream.send_recording_name(name)
        self.stream.send_blueprint(layout)
        self.stream.log(root, rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)

    @staticmethod
    def partial_path(path) -> Path:
        """Where the recording bound for ``path`` is streamed until it is closed (a hidden sibling);
        what a process stopped mid-recording leaves behind."""
        path = Path(path)
        return path.with_name(f".{path.name}.part")

    def close(self) -> None:
        """Flush everything logged, close the file (writing its footer) and give it its name.
        Idempotent."""
        self.stream.flush()
        self.stream.disconnect()
        Recording._open.discard(self)
        if self.partial.exists():
            os.replace(self.partial, self.path)

    def discard(self) -> None:
        """Stop recording and delete what was written (an interrupted run). Idempotent."""
        self.stream.disconnect()
        Recording._open.discard(self)
        self.partial.unlink(missing_ok=True)

    @classmethod
    def discard_open(cls) -> None:
        """Discard every recording not closed yet (what an interrupted command leaves)."""
        for recording in list(cls._open):
            recording.discard()

    def log_markdown(self, entity: str, text: str, static: bool = False) -> None:
        self.stream.log(entity, rr.TextDocument(text, media_type=rr.MediaType.MARKDOWN), static=static)


class RelaxRecording(Recording):
    """Records relaxations of a periodic yarn repeat to a ``.rrd`` file (see the module docstring
    for the entity paths and the timeline).

    Use the instance itself as the ``on_iteration`` callback of ``relax_pattern``; call :meth:`start`
    before each relaxation and :meth:`finish` once with the result.

    Args:
        name: recording name shown by the viewer (e.g. the fabric's name).
        path: the ``.rrd`` file to write; its directory is created.
    """

    def __init__(self, name: str, path) -> None:
        super().__init__(name, path, blueprint(), "relax")
        self._step = -1  # last position used on the timeline
        # Topology of the current relaxation, set by start(): node gather and closing shifts of
        # the strips, strip ends, tile shifts and strip ends of the tiling.
        self._n_nodes = 0
        self._gather = self._shift = self._ends = self._tile_shift = self._tile_ends = None

    # -- relaxation hooks -----------------------------------------------------------------------

    def start(self, pattern: YarnPattern) -> None:
        """Begin a relaxation of ``pattern`` (unrelaxed): remember its yarn topology and log,
        at the next timeline step, the radius, colours, tile outline and the unrelaxed yarns."""
        yarns = pattern.yarns()
        lattice = pattern.lattice
        self._n_nodes = pattern.n_nodes
        self._gather, self._shift, self._ends = _strip_layout(yarns, lattice)
        self._tile_shift = _TILES @ lattice  # (9, 3) m
        # The tiling is the strips of tile 0, then of tile 1, ...: the same cuts, tile by tile.
        self._tile_ends = (np.arange(len(_TILES))[:, None] * self._ends[-1] + self._ends[None, :]).ravel()

        self._advance()
        radius = np.float32(pattern.radius)
        self.stream.log("relax/repeat/yarns", rr.LineStrips3D.from_fields(radii=radius, colors=_yarn_colors(len(yarns))))
        self.stream.log("relax/tiling/yarns", rr.LineStrips3D.from_fields(radii=radius,
                                                                        colors=_tiling_colors(len(yarns))))
        outline = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0, 0]], dtype=np.float64) @ lattice
        self.stream.log("relax/repeat/tile", rr.LineStrips3D([outline], radii=TILE_LINE_RADIUS * radius,
                                                           colors=NEIGHBOUR_COLOR))
        self._log_yarns(pattern.node_position[np.concatenate([y.nodes for y in yarns])])

    def __call__(self, progress: Progress) -> None:
        """Progress callback: log the yarns, residuals and potential of one Newton iteration."""
        self._advance()
        self._log_yarns(progress.position)
        residual = progress.residual
        for key in RESIDUALS:
            self.stream.log(f"relax/residual/{key}", rr.Scalars(float(getattr(residual, key))))
        self.stream.log("relax/energy/potential", rr.Scalars(float(progress.potential)))

    def finish(self, result) -> None:
        """Log the relaxed repeat ``result`` (a :class:`yarnfit.relax.RelaxedRepeat`): its yarns,
        energy terms and a summary, at the step after the last; then close the file."""
        self._advance()
        # The rest model keeps the phase-1 node layout (rods in yarn order), as progress does.
        self._log_yarns(result.state.node_position)
        for key in ENERGY_TERMS:
            self.stream.log(f"relax/energy/{key}", rr.Scalars(float(getattr(result.energy, key))))
        self.log_markdown("relax/summary", summary(result))
        self.close()

    # -- helpers --------------------------------------------------------------------------------

    def _advance(self) -> None:
        self._step += 1
        self.stream.set_time(TIMELINE, sequence=self._step)

    def _log_yarns(self, position: np.ndarray) -> None:
        """Log the closed yarn strips of ``position`` ``(N, 3)`` m (yarn order) and their tiling."""
        if self._gather is None:
            raise RuntimeError("RelaxRecording.start(pattern) must be called before logging yarns")
        position = np.asarray(position, dtype=np.float64)
        if position.shape != (self._n_nodes, 3):
            raise ValueError(f"expected yarn positions of shape ({self._n_nodes}, 3), got {position.shape}")
        points = position[self._gather] + self._shift
        self.stream.log("relax/repeat/yarns", rr.LineStrips3D.from_fields(strips=np.split(points, self._ends[:-1])))
        tiled = (points[None] + self._tile_shift[:, None]).reshape(-1, 3)
        self.stream.log("relax/tiling/yarns", rr.LineStrips3D.from_fields(strips=np.split(tiled, self._tile_ends[:-1])))


class FitRecording(Recording):
    """Records a shell fit run — the relaxed repeat, every homogenization sample, the fit curves
    and a summary — to a ``.rrd`` file (see the module docstring for the entity paths and the
    ``sample`` timeline).

    Call :meth:`start` once with the relaxed repeat, :meth:`sample` for each solved sample (in any
    order) and :meth:`finish` once with the :class:`yarnfit.fabric_fit.FabricFit`, which closes the
    file.

    Args:
        name: recording name shown by the viewer (e.g. the fabric's name).
        path: the ``.rrd`` file to write; its directory is created.
    """

    def __init__(self, name: str, path) -> None:
        super().__init__(name, path, fit_blueprint(), "fit")

    def start(self, relaxed) -> None:
        """Log the relaxed repeat (a :class:`yarnfit.relax.RelaxedRepeat`) as static yarn strips
        in its flat tile, positions in m."""
        strips = yarn_strips(relaxed.model, relaxed.state.node_position)
        self.stream.log("fit/relaxed/yarns", rr.LineStrips3D(strips, radii=np.float32(relaxed.radius),
                                                           colors=_yarn_colors(len(strips))), static=True)

    def sample(self, index: int, relaxed, result) -> None:
        """Log sample ``index`` (0-based, in design order) at that step of the ``sample`` timeline:
        its equilibrium ``result.position`` ``(N, 3)`` m in 3 × 3 tiles of the curved tiling that
        ``tile_repeat(relaxed, I, II)`` builds for it (where known), its Ū (J/m²) and its numbers.

        Args:
            index: the sample's index in ``FabricFit.samples`` (design order).
            relaxed: the :class:`yarnfit.relax.RelaxedRepeat` the sample was solved on.
            result: the :class:`yarnfit.samples.SampleResult`.
        """
        if isinstance(index, bool) or not isinstance(index, (int, np.integer)) or index < 0:
            raise ValueError(f"a sample index must be a non-negative integer, got {index!r}")
        spec = result.spec
        self.stream.set_time(SAMPLE_TIMELINE, sequence=int(index))
        if result.position is not None:
            # Without positions (a sample that did not converge, a frictional pull's: docs/design.md
            # §3) only its numbers are logged. The solver's model is rebuilt rather than shipped
            # back from the (worker) process: it is deterministic in (relaxed, I, II) and cheap
            # next to the solve.
            model = tile_repeat(relaxed, spec.I, spec.II).model
            position = np.asarray(result.position, dtype=np.float64)
            if position.shape != (model.n_nodes, 3):
                raise ValueError(f"expected sample positions of shape ({model.n_nodes}, 3), got {position.shape}")
            strips = [strip for tile in _TILE_OFFSETS for strip in yarn_strips(model, position, tile)]
            self.stream.log("fit/sample/yarns", rr.LineStrips3D(strips, radii=np.float32(relaxed.radius),
                                                              colors=_tiling_colors(model.n_rods)))
        self.stream.log("fit/sample/energy", rr.Scalars(float(result.energy_density)))
        self.log_markdown("fit/sample/info", sample_summary(int(index), result))

    def finish(self, fabric_fit) -> None:
        """Log the fit curves of every sampled family and the summary of ``fabric_fit`` (a
        :class:`yarnfit.fabric_fit.FabricFit`), all static; then close the file."""
        material = fabric_fit.material
        for family in FAMILIES:
            results = [r for r in fabric_fit.samples if r.spec.family == family]
            if results:
                self._log_curves(family, results, material, fabric_fit.fit.shell_energy(results))
        self.log_markdown("fit/summary", fit_summary(fabric_fit), static=True)
        self.close()

    def _log_curves(self, family: str, results, material, energy: np.ndarray) -> None:
        """Samples (parameter, Ū as the shell sees it: ``energy``, less the rest energy and the
        residual-stress terms) and the shell's curve (parameter, W) of one family, in the family's
        parameter unit and J/m², drawn through a transform that fits them to a unit box with y up
        (see the module docstring)."""
        parameter = np.array([r.spec.parameter for r in results], dtype=np.float64)
        energy = np.asarray(energy, dtype=np.float64)
        converged = np.array([r.converged for r in results], dtype=bool)
        curve_p, curve_w = shell_curve(material, family, parameter)
        plotted = np.isfinite(energy)
        excluded = ~converged & plotted
        p_extent = float(np.abs(curve_p).max())
        w_extent = float(np.abs(np.concatenate([energy[plotted], curve_w])).max(initial=0.0))
        display = rr.Transform3D(scale=[1.0 / p_extent if p_extent > 0 else 1.0,
                                        -1.0 / w_extent if w_extent > 0 else -1.0, 1.0])
        root = f"fit/curves/{family}"
        used = converged & plotted
        self.stream.log(f"{root}/yarn", rr.Points2D(np.column_stack([parameter[used], energy[used]]),
                                                  radii=SAMPLE_POINT_SIZE, colors=SAMPLE_COLOR), display, static=True)
        if excluded.any():
            self.stream.log(f"{root}/excluded", rr.Points2D(np.column_stack([parameter[excluded], energy[excluded]]),
                                                          radii=SAMPLE_POINT_SIZE, colors=EXCLUDED_COLOR),
                          display, static=True)
        self.stream.log(f"{root}/shell", rr.LineStrips2D([np.column_stack([curve_p, curve_w])], radii=SHELL_LINE_SIZE,
                                                       colors=SHELL_COLOR), display, static=True)


def shell_curve(material, family: Family, parameters) -> tuple[np.ndarray, np.ndarray]:
    """The shell's energy density along ``family``: parameters ``p (n,)`` (the family's unit) on
    a uniform grid of CURVE_POINTS spanning ``parameters`` and 0, plus ``parameters`` themselves
    (so the curve passes exactly through the shell's value at every sample), and ``W(p) (n,)``
    (J/m²) of ``material`` (a :class:`yarnfit.shell.ShellMaterial`)."""
    parameters = np.asarray(parameters, dtype=np.float64)
    low, high = min(0.0, float(parameters.min())), max(0.0, float(parameters.max()))
    grid = np.linspace(low, high, CURVE_POINTS)
    # A sample on a grid point but for round-off (2.5 % from a log design against 25 × 0.1 %)
    # would be a second point there, and one point in the recording's float32.
    apart = np.abs(grid[:, None] - parameters[None, :]).min(axis=1) > CURVE_MERGE_REL * (high - low)
    p = np.union1d(grid[apart], parameters)
    family = Family.named(family)
    if family.uniaxial_angle is not None:
        # The shell's own free strains: the Schur complement along a yarn axis, its own free pull
        # on the bias; not the yarn-level sample's.
        energy = []
        flat = np.zeros((2, 2))
        for value in p:
            try:
                if family.uniaxial_axis is not None:
                    energy.append(material.uniaxial_tension(family.uniaxial_axis, 1.0 + value)[1])
                else:
                    pull = material.uniaxial_pull(family.uniaxial_angle, 1.0 + value)
                    energy.append(float(material.energy_density(pull.first_form, flat)))
            except ValueError:
                # Beyond here no free width balances the pull (the width collapses: polyester
                # satin's weft at 26 %, as its yarn-level sample at 40 % contracted past half its
                # width): the curve ends there, as the tension figure's does.
                break
        return p[:len(energy)], np.asarray(energy, dtype=np.float64)
    forms = [family.deformation(value) for value in p]
    energy = material.energy_density(np.array([I for I, _ in forms]), np.array([II for _, II in forms]))
    return p, np.asarray(energy, dtype=np.float64)


def _yarn_colors(n_yarns: int) -> np.ndarray:
    """``(n_yarns, 3)`` RGB, one colour per yarn."""
    return YARN_COLORS[np.arange(n_yarns) % len(YARN_COLORS)]


def _tiling_colors(n_yarns: int) -> np.ndarray:
    """``(9 n_yarns, 3)`` RGB for the strips of a 3 × 3 tiling, tile by tile: the centre tile in
    the yarn colours, its neighbours grey."""
    colors = np.repeat(NEIGHBOUR_COLOR[None], len(_TILES) * n_yarns, axis=0)
    colors[_CENTRE * n_yarns:(_CENTRE + 1) * n_yarns] = _yarn_colors(n_yarns)
    return colors


def _strip_layout(yarns, lattice: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """How to turn yarn-order positions ``p (N, 3)`` into closed strips: ``p[gather] + shift``
    ``(N + Y, 3)`` cut at ``ends`` (Y,) is each yarn's nodes followed by its first node moved by
    the yarn's net tile offset ``net_offset @ lattice``. Yarn k owns rows ``first[k]:first[k] +
    count[k]`` of ``p``."""
    count = np.array([len(y.nodes) for y in yarns])
    first = np.cumsum(count) - count
    gather = np.concatenate([np.append(np.arange(f, f + n), f) for f, n in zip(first, count)])
    ends = np.cumsum(count + 1)
    shift = np.zeros((len(gather), 3))
    shift[ends - 1] = np.array([y.net_offset for y in yarns], dtype=np.float64) @ lattice
    return gather, shift, ends


# -- markdown summaries ----------------------------------------------------------------------------


def markdown_table(rows, header=("quantity", "value")) -> str:
    """A markdown table of ``rows`` (tuples of cells, as many as ``header``)."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(cell) for cell in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def _converged(flag: bool) -> str:
    return "yes" if flag else "**no**"


def summary(result) -> str:
    """Markdown summary of a relaxed repeat (display units: mm, µm, m/m², g/m²)."""
    px, py = (1e3 * float(v) for v in result.repeat_size)
    r = result.residual
    rows = [
        ("repeat size", f"{px:.4g} × {py:.4g} mm"),
        ("yarn radius", f"{1e6 * result.radius:.4g} µm"),
        *yarn_rows(result.yarn),
        ("yarn length per area", f"{result.yarn_length_per_area:.5g} m/m²"),
        ("areal density", f"{1e3 * result.areal_density:.4g} g/m²"),
        ("residual force / torque", f"{r.force:.3g} / {r.torque:.3g}"),
        ("residual energy change / penetration", f"{r.energy_change:.3g} / {r.penetration:.3g}"),
        ("worst penetration", f"{100 * result.penetration:.3g} % of the diameter"),
        ("converged", _converged(result.converged)),
        ("iterations (last relaxation)", f"{result.iterations}"),
        ("relaxations", f"{result.relaxations}"),
        ("wall time", f"{result.seconds:.3g} s"),
    ]
    return f"## Relaxed repeat\n\n{markdown_table(rows)}"


def yarn_rows(yarn) -> list[tuple[str, str]]:
    """Rows of a :class:`yarnfit.yarn.Yarn` in textile units beside SI."""
    fibres = "–" if yarn.fibres_per_section is None else f"{yarn.fibres_per_section:.0f}"
    return [
        ("yarn model", yarn.model + ("" if yarn.spinning is None else f", {yarn.spinning}")),
        ("linear density / fibres per section", f"{yarn.linear_density_tex:.4g} tex / {fibres}"),
        ("packing fraction / surface twist", f"{yarn.packing_fraction:.3g} / {yarn.twist_angle_deg:.3g}°"),
        ("tensile rigidity EA", f"{yarn.tensile_rigidity_n:.4g} N"),
        ("bending rigidity EI", f"{yarn.bending_rigidity_nm2:.4g} N·m² ({1e9 * yarn.bending_rigidity_nm2:.4g} mN·mm²)"),
        ("torsional rigidity GJ", f"{yarn.torsional_rigidity_nm2:.4g} N·m² "
                                  f"({1e9 * yarn.torsional_rigidity_nm2:.4g} mN·mm²)"),
        ("EI / solid rod of the same mass", f"{yarn.bending_vs_solid:.3g}"),
    ]


def _matrix(m) -> str:
    """A 2 × 2 matrix on one line: ``[[a, b], [c, d]]``."""
    return "[" + ", ".join("[" + ", ".join(f"{v:.6g}" for v in row) + "]" for row in np.asarray(m)) + "]"


def sample_summary(index: int, result) -> str:
    """Markdown summary of sample ``index`` (a :class:`yarnfit.samples.SampleResult`):
    parameter in its family's unit, II in 1/m, Ū in J/m²."""
    spec, r = result.spec, result.residual
    rows = [
        ("family", spec.family),
        (f"parameter ({spec.family.label})", f"{spec.parameter:.6g}"),
        ("I", _matrix(spec.I)),
        ("II (1/m)", _matrix(spec.II)),
        ("Ū", f"{result.energy_density:.6g} J/m²"),
        ("converged", _converged(result.converged)),
        ("iterations", f"{result.iterations}"),
        ("residual force / torque", f"{r.force:.3g} / {r.torque:.3g}"),
        ("residual energy change / penetration", f"{r.energy_change:.3g} / {r.penetration:.3g}"),
        ("wall time", f"{result.seconds:.3g} s"),
    ]
    return f"## Sample {index}\n\n{markdown_table(rows)}"


# Engineering constants as the summary shows them: key of ShellMaterial.engineering(), label, SI
# unit and, for the bending rigidities, the textile unit (gf·cm²/cm, the KES-F convention).
_CONSTANTS = (
    ("weft_stretch_n_per_m", "weft stretch", "N/m"),
    ("warp_stretch_n_per_m", "warp stretch", "N/m"),
    ("poisson_weft", "Poisson ratio weft", ""),
    ("poisson_warp", "Poisson ratio warp", ""),
    ("shear_n_per_m", "in-plane shear", "N/m"),
    ("bending_weft_nm", "bending weft", "N·m"),
    ("bending_warp_nm", "bending warp", "N·m"),
    ("bending_bias_nm", "bending bias", "N·m"),
)


def fit_summary(fabric_fit) -> str:
    """Markdown summary of a shell fit (a :class:`yarnfit.fabric_fit.FabricFit`): engineering
    constants in SI and user units (N/m; gf·cm²/cm for bending), R² and relative RMS per sampled
    family, model, thickness (mm), sample counts and wall time per stage (s)."""
    fit, material = fabric_fit.fit, fabric_fit.material
    try:
        engineering = material.engineering()
    except ValueError as error:
        # A shell that is not positive definite has no engineering constants; the recording
        # should still say what the fit produced rather than fail after the run.
        constants = f"not available: {error}\n"
    else:
        rows = []
        for key, label, unit in _CONSTANTS:
            value = engineering[key]
            si = f"{value:.5g} {unit}".rstrip()
            user = f"{value / GF_CM2_PER_CM:.5g} gf·cm²/cm" if unit == "N·m" else si
            rows.append((label, si, user))
        constants = markdown_table(rows, header=("constant", "SI", "user units"))
    quality = [(family, f["samples"], f"{f['r2']:.6g}", f"{f['relative_rms']:.3g}")
               for family, f in fit.families.items() if f["samples"] > 0]
    samples = fabric_fit.samples
    converged = sum(bool(r.converged) for r in samples)
    seconds = fabric_fit.seconds
    run = [
        ("fabric", fabric_fit.fabric.name),
        *yarn_rows(fabric_fit.relaxed.yarn),
        ("model", fit.model),
        ("thickness", f"{1e3 * material.thickness:.4g} mm"),
        ("samples", f"{len(samples)} ({converged} converged, {len(fit.used)} fitted, {len(fit.excluded)} excluded)"),
        ("stretch range / curvature range", f"{fabric_fit.ranges.stretch:.4g} / {fabric_fit.ranges.curvature:.4g} 1/m"),
        ("active bounds", ", ".join(fit.active_bounds) or "none"),
        ("wall time relax / homogenize / fit",
         " / ".join(f"{seconds.get(stage, math.nan):.3g}" for stage in ("relax", "homogenize", "fit")) + " s"),
    ]
    notes = "".join(f"- {note}\n" for note in fit.notes)
    return (f"## Shell fit\n\n### Engineering constants\n\n{constants}\n### Fit quality\n\n"
            f"{markdown_table(quality, header=('family', 'samples', 'R²', 'relative RMS'))}\n"
            + (f"### Bounds reached\n\n{notes}\n" if notes else "")
            + f"### Run\n\n{markdown_table(run)}")
