"""Rerun recordings of yarnfit runs.

A :class:`RelaxRecording` writes one relaxation run (phase 1, ``yarnfit.relax``) to one ``.rrd``
file through its own ``rr.RecordingStream`` (application id ``"yarnfit"``, recording name = the
run's name); the global recording is never touched. Open the file with ``rerun file.rrd``.

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
    result = relax_pattern(pattern, fabric.fiber, progress=recording)
    recording.finish(result)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from .engine import Progress
from .patterns import YarnPattern

APPLICATION_ID = "yarnfit"
TIMELINE = "iteration"

# Yarn colours (RGB), cycled by yarn index; neighbour tiles are drawn in a neutral grey so the
# repeat itself stands out in the tiling.
YARN_COLORS = np.array([[31, 119, 180], [255, 127, 14], [44, 160, 44], [214, 39, 40], [148, 103, 189],
                        [140, 86, 75], [227, 119, 194], [188, 189, 34], [23, 190, 207]], dtype=np.uint8)
NEIGHBOUR_COLOR = np.array([150, 150, 150], dtype=np.uint8)
# Tile outline width relative to the yarn radius: thin enough not to hide the yarns.
TILE_LINE_RADIUS = 0.1

RESIDUALS = ("force", "torque", "penetration", "energy_change")
ENERGY_TERMS = ("stretch", "shear", "bend", "twist", "external", "total")

# Tile shifts (i, j) of the 3 × 3 tiling, i, j ∈ {−1, 0, 1}; the centre (0, 0) is entry 4.
_TILES = np.array([(i, j) for i in (-1, 0, 1) for j in (-1, 0, 1)], dtype=np.float64)
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
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(state="expanded", timeline=TIMELINE),
    )


class RelaxRecording:
    """Records relaxations of a periodic yarn repeat to a ``.rrd`` file (see the module docstring
    for the entity paths and the timeline).

    Use the instance itself as the ``progress`` callback of ``relax_pattern``; call :meth:`start`
    before each relaxation and :meth:`finish` once with the result.

    Args:
        name: recording name shown by the viewer (e.g. the fabric's name).
        path: the ``.rrd`` file to write; its directory is created.
    """

    def __init__(self, name: str, path) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._rec = rr.RecordingStream(APPLICATION_ID)
        # The file sink must be attached before anything is logged, or that data is lost.
        self._rec.save(self.path)
        self._rec.send_recording_name(name)
        self._rec.send_blueprint(blueprint())
        self._rec.log("relax", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
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
        colors = YARN_COLORS[np.arange(len(yarns)) % len(YARN_COLORS)]
        tiling_colors = np.repeat(NEIGHBOUR_COLOR[None], len(_TILES) * len(yarns), axis=0)
        tiling_colors[_CENTRE * len(yarns):(_CENTRE + 1) * len(yarns)] = colors
        radius = np.float32(pattern.radius)
        self._rec.log("relax/repeat/yarns", rr.LineStrips3D.from_fields(radii=radius, colors=colors))
        self._rec.log("relax/tiling/yarns", rr.LineStrips3D.from_fields(radii=radius, colors=tiling_colors))
        outline = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0, 0]], dtype=np.float64) @ lattice
        self._rec.log("relax/repeat/tile", rr.LineStrips3D([outline], radii=TILE_LINE_RADIUS * radius,
                                                           colors=NEIGHBOUR_COLOR))
        self._log_yarns(pattern.node_position[np.concatenate([y.nodes for y in yarns])])

    def __call__(self, progress: Progress) -> None:
        """Progress callback: log the yarns, residuals and potential of one Newton iteration."""
        self._advance()
        self._log_yarns(progress.position)
        residual = progress.residual
        for key in RESIDUALS:
            self._rec.log(f"relax/residual/{key}", rr.Scalars(float(getattr(residual, key))))
        self._rec.log("relax/energy/potential", rr.Scalars(float(progress.potential)))

    def finish(self, result) -> None:
        """Log the relaxed repeat ``result`` (a :class:`yarnfit.relax.RelaxedRepeat`): its yarns,
        energy terms and a summary, at the step after the last; then close the file."""
        self._advance()
        # The rest model keeps the phase-1 node layout (rods in yarn order), as progress does.
        self._log_yarns(result.state.node_position)
        for key in ENERGY_TERMS:
            self._rec.log(f"relax/energy/{key}", rr.Scalars(float(getattr(result.energy, key))))
        self._rec.log("relax/summary", rr.TextDocument(summary(result), media_type=rr.MediaType.MARKDOWN))
        self.close()

    def close(self) -> None:
        """Flush everything logged and close the file (writing its footer). Idempotent."""
        self._rec.flush()
        self._rec.disconnect()

    # -- helpers --------------------------------------------------------------------------------

    def _advance(self) -> None:
        self._step += 1
        self._rec.set_time(TIMELINE, sequence=self._step)

    def _log_yarns(self, position: np.ndarray) -> None:
        """Log the closed yarn strips of ``position`` ``(N, 3)`` m (yarn order) and their tiling."""
        if self._gather is None:
            raise RuntimeError("RelaxRecording.start(pattern) must be called before logging yarns")
        position = np.asarray(position, dtype=np.float64)
        if position.shape != (self._n_nodes, 3):
            raise ValueError(f"expected yarn positions of shape ({self._n_nodes}, 3), got {position.shape}")
        points = position[self._gather] + self._shift
        self._rec.log("relax/repeat/yarns", rr.LineStrips3D.from_fields(strips=np.split(points, self._ends[:-1])))
        tiled = (points[None] + self._tile_shift[:, None]).reshape(-1, 3)
        self._rec.log("relax/tiling/yarns", rr.LineStrips3D.from_fields(strips=np.split(tiled, self._tile_ends[:-1])))


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


def summary(result) -> str:
    """Markdown summary of a relaxed repeat (display units: mm, µm, m/m², g/m²)."""
    px, py = (1e3 * float(v) for v in result.repeat_size)
    r = result.residual
    rows = [
        ("repeat size", f"{px:.4g} × {py:.4g} mm"),
        ("yarn radius", f"{1e6 * result.radius:.4g} µm"),
        ("yarn length per area", f"{result.yarn_length_per_area:.5g} m/m²"),
        ("areal density", f"{1e3 * result.areal_density:.4g} g/m²"),
        ("residual force / torque", f"{r.force:.3g} / {r.torque:.3g}"),
        ("residual energy change / penetration", f"{r.energy_change:.3g} / {r.penetration:.3g}"),
        ("worst penetration", f"{100 * result.penetration:.3g} % of the diameter"),
        ("converged", "yes" if result.converged else "**no**"),
        ("iterations (last relaxation)", f"{result.iterations}"),
        ("relaxations", f"{result.relaxations}"),
        ("wall time", f"{result.seconds:.3g} s"),
    ]
    table = "\n".join(f"| {key} | {value} |" for key, value in rows)
    return f"## Relaxed repeat\n\n| quantity | value |\n|---|---|\n{table}\n"
