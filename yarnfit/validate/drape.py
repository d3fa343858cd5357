"""Sphere and wall drapes of a fitted material in MuJoCo (issue 6, item 4).

* ``sphere``: a 30 × 30 cm swatch (weft along x) dropped centred on a sphere of radius 9 cm (the
  exported ``sphere`` scene at ``size`` 0.3 m: radius 0.3 size) until it is at rest.
* ``wall``: the same swatch hanging from its two pinned corners at ``x = −size/2`` (the exported
  ``cloth`` scene) next to a wall, a box whose face is :data:`WALL_GAP` behind the pinned edge.

A drape is at rest when its kinetic energy per unit mass falls below :data:`REST_SPEED`² / 2, or
after :data:`MAX_SECONDS` (reported as not settled). Summaries (keys carry units):

- ``drape_coefficient``: projected area (on the floor plane, z) over the swatch's area;
- ``lowest_point_m``: lowest vertex height;
- ``fold_count`` (sphere): maxima of the hem's radius around the sphere's axis with a
  prominence of at least :data:`FOLD_PROMINENCE` of the swatch's size;
- ``weft_warp_asymmetry`` (sphere): (extent along x − extent along y) / their mean, of the
  projection;
- ``max_distance_from_wall_m`` (wall): how far the hanging swatch stands off the wall;
- ``settled``, ``simulated_s``, ``wall_seconds``, ``ms_per_step``, ``bad_qacc``.

Recording (``logs/<material>/<scene>.rrd``): timeline ``sim_time`` (s); entity paths

- ``<scene>/cloth``: ``Mesh3D``, the swatch (m);
- ``<scene>/bodies/obstacle``: the sphere (``Ellipsoids3D``) or the wall (``Boxes3D``), static;
- ``<scene>/plots/kinetic_energy``: ``Scalars``, kinetic energy per unit mass (J/kg);
- ``<scene>/plots/lowest_point``: ``Scalars``, lowest vertex height (m);
- ``<scene>/summary``: ``TextDocument`` (markdown).

The final mesh is also written as ``<scene>_final.ply`` beside the recording.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable

import numpy as np
import rerun as rr
import rerun.blueprint as rrb
from scipy.signal import find_peaks

from ..mujoco.scenes import ClothMaterial, build_scene, compile_quietly
from ..record import Recording, markdown_table
from . import NOT_SUMMARISED, OPTIONAL, SceneResult

SIZE = 0.3  # m: the swatch's side
# Vertices per side: 1.5 cm and 2.5 cm cells. Finer is not stable at the export's 1 ms step: the
# plugin's explicit bending injects energy (a cotton jersey on 1 cm cells slid off the sphere and
# skated 1.4 m over the floor in 4 s; on 1.25 cm cells it never came to rest; on 1.5 cm it settles
# in 1.4 s with the quick mesh's drape coefficient). One diagonal per cell (scenes.grid_mesh): such meshes
# lock in plane on the bias of shear-soft wovens (design notes §7), but the plugin's hinge-based
# shape operator is exact on them for cylinders along the grid, while on criss-cross cells it
# scatters by ±50 % per triangle and overestimates the bending energy up to 1.8 times.
RESOLUTION = {False: 21, True: 13}
MESH = "grid"
# Rest: speed scale (m/s) of the kinetic energy per mass at which a drape counts as settled.
REST_SPEED = 5e-3
MAX_SECONDS = {False: 4.0, True: 1.5}
WALL_GAP = 0.01  # m between the pinned edge and the wall's face
# A fold is a maximum of the hem radius standing out by 2 % of the swatch's size (6 mm): smaller
# ripples are mesh-scale.
FOLD_PROMINENCE = 0.02
FRAMES_PER_SECOND = 30  # recorded meshes per simulated second
RASTER = 400  # projected-area raster cells per side


def projected_area(positions: np.ndarray, triangles: np.ndarray, cells: int = RASTER) -> float:
    """Area (m²) of the union of the triangles' projections onto the xy plane, by rasterising the
    bounding box into ``cells × cells`` centres."""
    xy = positions[:, :2]
    low, high = xy.min(0), xy.max(0)
    step = (high - low) / cells
    grid = np.stack(np.meshgrid(low[0] + step[0] * (np.arange(cells) + 0.5),
                                low[1] + step[1] * (np.arange(cells) + 0.5), indexing="ij"), -1)
    covered = np.zeros((cells, cells), bool)
    for a, b, c in xy[triangles]:
        lo = np.maximum(((np.minimum(np.minimum(a, b), c) - low) / step).astype(int), 0)
        hi = np.minimum(((np.maximum(np.maximum(a, b), c) - low) / step).astype(int) + 1, cells)
        points = grid[lo[0]:hi[0], lo[1]:hi[1]]
        d = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1])
        if d == 0:
            continue
        p = points - a
        u = (p[..., 0] * (c[1] - a[1]) - p[..., 1] * (c[0] - a[0])) / d
        v = (p[..., 1] * (b[0] - a[0]) - p[..., 0] * (b[1] - a[1])) / d
        covered[lo[0]:hi[0], lo[1]:hi[1]] |= (u >= 0) & (v >= 0) & (u + v <= 1)
    return float(covered.sum() * step[0] * step[1])


def fold_count(positions: np.ndarray, boundary: np.ndarray, size: float) -> int:
    """Folds around the z axis through the origin: prominent maxima of the hem's radius as a
    function of angle (360 one-degree bins, periodic)."""
    xy = positions[boundary, :2]
    angle = np.degrees(np.arctan2(xy[:, 1], xy[:, 0])) % 360
    radius = np.hypot(xy[:, 0], xy[:, 1])
    profile = np.full(360, np.nan)
    for k in range(360):
        inside = (angle >= k) & (angle < k + 1)
        if inside.any():
            profile[k] = radius[inside].max()
    known = ~np.isnan(profile)
    profile = np.interp(np.arange(360), np.flatnonzero(known), profile[known], period=360)
    tripled = np.concatenate([profile] * 3)  # periodic: count peaks in the middle copy
    peaks, _ = find_peaks(tripled, prominence=FOLD_PROMINENCE * size)
    return int(((peaks >= 360) & (peaks < 720)).sum())


@dataclass(frozen=True)
class DrapeResult(SceneResult):
    """A drape at rest (or at the time limit): the drape coefficient (projected area over the
    swatch's, dimensionless), the lowest point (m), whether it ``settled``, simulated and wall time
    (s), ms per step, MuJoCo's bad-QACC warnings, the mesh resolution; on the sphere the fold count
    and the weft/warp extent asymmetry, on the wall the largest distance from it (m); the final
    mesh file if one was written, and the final vertex positions ``(n, 3)`` (m) and triangles."""

    drape_coefficient: float
    lowest_point_m: float
    settled: bool
    simulated_s: float
    wall_seconds: float
    ms_per_step: float
    bad_qacc: int
    resolution: int
    fold_count: int | None = field(default=None, metadata=OPTIONAL)
    weft_warp_asymmetry: float | None = field(default=None, metadata=OPTIONAL)
    max_distance_from_wall_m: float | None = field(default=None, metadata=OPTIONAL)
    final_mesh: str | None = field(default=None, metadata=OPTIONAL)
    positions: np.ndarray | None = field(default=None, repr=False, metadata=NOT_SUMMARISED)
    triangles: np.ndarray | None = field(default=None, repr=False, metadata=NOT_SUMMARISED)


def run_drape(material: ClothMaterial | str | Path, scene: str, *, quick: bool = False, recording_path=None,
              progress: Callable[[str], None] | None = None) -> DrapeResult:
    """Drop (``sphere``) or hang (``wall``) the swatch until at rest. With a ``recording_path``, the
    final mesh is also written beside it as ``<scene>_final.ply`` (m; ``final_mesh``)."""
    result = drape(material, scene, quick=quick, recording_path=recording_path, progress=progress)
    if recording_path:
        import trimesh

        final = Path(recording_path).with_name(f"{scene}_final.ply")
        trimesh.Trimesh(result.positions, result.triangles, process=False).export(final)
        result = replace(result, final_mesh=str(final))
    return result


def drape(material: ClothMaterial | str | Path, scene: str, *, quick: bool = False, recording_path=None,
          progress: Callable[[str], None] | None = None) -> DrapeResult:
    """:func:`run_drape`'s simulation (no mesh file written)."""
    import mujoco

    if scene not in ("sphere", "wall"):
        raise ValueError(f"unknown drape {scene!r}; drapes: sphere, wall")
    if not isinstance(material, ClothMaterial):
        material = ClothMaterial.from_file(material)
    resolution = RESOLUTION[quick]
    built = build_scene(material, "sphere" if scene == "sphere" else "cloth", resolution=resolution, size=SIZE,
                        mesh=MESH)
    spec = built.spec
    if scene == "wall":
        spec.worldbody.add_geom(name="wall", type=mujoco.mjtGeom.mjGEOM_BOX,
                                size=[0.01, SIZE, 0.5 * (2 * SIZE + 0.1)],
                                pos=[-0.5 * SIZE - WALL_GAP - 0.01, 0.0, 0.5 * (2 * SIZE + 0.1)],
                                rgba=[0.6, 0.6, 0.65, 1])
        spec.flexes[0].contype = spec.flexes[0].conaffinity = 1
    model = compile_quietly(spec)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    triangles = model.flex_elem.reshape(-1, 3).copy()
    mass = float(model.body_mass[model.flex_vertbodyid].sum())
    recording = _DrapeRecording(material.name, scene, recording_path, model) if recording_path else None
    dt = model.opt.timestep
    frame_every = max(1, round(1.0 / (FRAMES_PER_SECOND * dt)))
    steps = round(MAX_SECONDS[quick] / dt)
    settled, start = False, time.perf_counter()
    step = 0
    for step in range(1, steps + 1):
        mujoco.mj_step(model, data)
        if step % frame_every == 0 or step == steps:
            mujoco.mj_forward(model, data)
            kinetic = _kinetic(model, data)
            if recording:
                recording.frame(step * dt, data.flexvert_xpos, triangles, kinetic / mass)
            if progress and step % (10 * frame_every) == 0:
                progress(f"{scene} drape: {step * dt:.2f} s simulated")
            if step * dt > 0.3 and kinetic / mass < 0.5 * REST_SPEED**2:
                settled = True
                break
    wall_seconds = time.perf_counter() - start
    mujoco.mj_forward(model, data)
    x = data.flexvert_xpos.copy()
    figures = {}
    if scene == "sphere":
        edges = np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]), 1)
        unique, count = np.unique(edges, axis=0, return_counts=True)
        boundary = np.unique(unique[count == 1])
        extent = np.ptp(x[:, :2], axis=0)
        figures = {"fold_count": fold_count(x, boundary, SIZE),
                   "weft_warp_asymmetry": float((extent[0] - extent[1]) / extent.mean())}
    else:
        wall_face = -0.5 * SIZE - WALL_GAP
        figures = {"max_distance_from_wall_m": float((x[:, 0] - wall_face).max())}
    result = DrapeResult(
        drape_coefficient=projected_area(x, triangles) / SIZE**2,
        lowest_point_m=float(x[:, 2].min()),
        settled=settled,
        simulated_s=step * dt,
        wall_seconds=wall_seconds,
        ms_per_step=1e3 * wall_seconds / max(step, 1),
        bad_qacc=int(data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number),
        resolution=resolution,
        positions=x,
        triangles=triangles,
        **figures,
    )
    if recording:
        recording.finish(result.summary())
    return result


def _kinetic(model, data) -> float:
    """Kinetic energy (J) of the cloth's vertex bodies (slide joints: ½ m v²)."""
    import mujoco

    energy = 0.0
    velocity = np.zeros(6)
    for body in np.unique(model.flex_vertbodyid):
        if model.body_dofnum[body] == 0:
            continue
        mujoco.mj_objectVelocity(model, data, mujoco.mjtObj.mjOBJ_BODY, body, velocity, 0)
        energy += 0.5 * model.body_mass[body] * float(velocity[3:] @ velocity[3:])
    return energy


class _DrapeRecording(Recording):
    """``logs/<material>/<scene>.rrd`` (see the module docstring)."""

    def __init__(self, name: str, scene: str, path, model) -> None:
        import mujoco

        layout = rrb.Blueprint(rrb.Horizontal(
            rrb.Spatial3DView(origin=scene, contents=[f"+ {scene}/**", f"- {scene}/plots/**"], name="drape"),
            rrb.Vertical(rrb.TimeSeriesView(origin=f"{scene}/plots", name="settling"),
                         rrb.TextDocumentView(origin=f"{scene}/summary", name="summary")),
        ))
        super().__init__(name, path, layout, scene)
        self.scene = scene
        geom = model.geom(scene if scene == "wall" else "sphere")
        if geom.type[0] == mujoco.mjtGeom.mjGEOM_SPHERE:
            self.stream.log(f"{scene}/bodies/obstacle", rr.Ellipsoids3D(centers=[geom.pos], half_sizes=[[geom.size[0]] * 3],
                                                                      fill_mode="solid"), static=True)
        else:
            self.stream.log(f"{scene}/bodies/obstacle", rr.Boxes3D(centers=[geom.pos], half_sizes=[geom.size],
                                                                 fill_mode="solid"), static=True)

    def frame(self, t: float, positions, triangles, kinetic_per_mass: float) -> None:
        self.stream.set_time("sim_time", duration=t)
        self.stream.log(f"{self.scene}/cloth", rr.Mesh3D(vertex_positions=positions, triangle_indices=triangles))
        self.stream.log(f"{self.scene}/plots/kinetic_energy", rr.Scalars(kinetic_per_mass))
        self.stream.log(f"{self.scene}/plots/lowest_point", rr.Scalars(float(positions[:, 2].min())))

    def finish(self, summary: dict) -> None:
        rows = [(k, f"{v:.4g}" if isinstance(v, float) else v) for k, v in summary.items()]
        self.log_markdown(f"{self.scene}/summary", markdown_table(rows), static=True)
        self.close()
