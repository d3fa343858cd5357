"""Full-body scene (issue 6): a T-shirt and pants of fitted materials on a humanoid whose joints
follow a scripted motion.

The body is ``mjcf/humanoid.xml`` (capsules, position actuators, gravity compensated; see the
file's comments for joints and motion). The garments are **flat panels** sewn together, as a
tailor makes them: each garment is a front and a back panel cut from the same pattern (a regular
triangle grid of spacing :data:`SPACING` / :data:`QUICK_SPACING`, built with ``trimesh``), the
front in the plane ``x = +d``, the back in ``x = −d``, around the body in its T-pose rest. Each
panel is its own flat 2D flex with the ``yarnfit.shell`` plugin (built by
:func:`yarnfit.mujoco.scenes.add_cloth_flex`): its rest shape is the flat pattern, its bending rest
is flat, so there is no prestress from the construction. Seams are MuJoCo ``connect`` equalities
between a site on each front seam vertex and the back vertex cut at the same pattern point
(soft at first, :data:`SEAM_SOLREF`, then as stiff as the contacts: :func:`seam_time_constant`): in
the first :data:`SETTLE_S` seconds, with the body at rest, they pull the panels together around
the body ("virtual sewing"); the motion starts afterwards. The panels have one diagonal per grid
cell, so knit garments are somewhat stiffer in plane than their material (design notes §7).

* Shirt: a T-shaped pattern (torso and sleeves), sewn along the sides, under the sleeves and over
  the shoulders and sleeves; open at the hem, the neck and the sleeve ends. Weft horizontal.
* Pants: a Π-shaped pattern (waist, two legs apart below the crotch), sewn along the outer sides
  and the inseams; open at the waist and the leg ends. The waistband's middle (|y| <
  :data:`WAIST_PIN_HALF_WIDTH`) is held on the pelvis by ``connect`` equalities (a belt).
  Weft horizontal.

Why panels and not a tube mesh: the plugin's rest frame is triangle 0's plane and every
triangle's rest edges are projected into it, so a curved rest mesh gets a wrong rest metric (a
tube's triangles turned 90° from triangle 0 would be degenerate). Single-flex garments need the
plugin to take per-triangle rest coordinates from the pattern (e.g. the flex's texture
coordinates).

Checks (after :data:`SETTLE_S`): MuJoCo's bad-QACC warning count and non-finite positions;
penetration = largest depth of a garment vertex inside any capsule (m; target
:data:`PENETRATION_TARGET`); distance = largest distance of a garment vertex from the body
surface, i.e. from its nearest capsule (m; target :data:`DISTANCE_TARGET`); wall time, ms/step.

Recording (``recording_path``, e.g. ``logs/<material>/body.rrd``; one ``RecordingStream``,
application id ``"yarnfit"``), timeline ``sim_time`` (s), one frame every :data:`FRAME_S`:

- ``body``: ``ViewCoordinates`` right-handed, z up (static).
- ``body/cloth/shirt``, ``body/cloth/pants``: ``Mesh3D``, triangles and colour static, vertex
  positions (m) per frame (both panels of the garment in one mesh: front vertices first).
- ``body/bodies/<geom name>``: ``Capsules3D``, one per humanoid capsule (``pelvis``, ``torso``,
  ``head``, ``l_upper_arm`` …), per frame.
- ``body/plots/penetration``, ``body/plots/distance``: ``Scalars`` (m), the largest penetration
  and distance of the frame.
- ``body/summary``: ``TextDocument`` (markdown), the results (at the end).

The blueprint opens on the 3D view of ``body`` beside the two plots and the summary.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import mujoco
import numpy as np
import rerun as rr
import rerun.blueprint as rrb
import trimesh

from ..engine.rotations import quaternion_between, xyzw
from ..mujoco import DEFAULT_DAMPING, DEFAULT_FRICTION
from ..mujoco.scenes import FLEX_RADIUS, ClothMaterial, add_cloth_flex, compile_quietly
from ..record import Recording, folded_panels, markdown_table
from . import OPTIONAL, SceneResult

__all__ = ["BodyResult", "HUMANOID", "MOTION", "build_body_scene", "garment_panel", "motion_targets", "run_body"]

HUMANOID = Path(__file__).resolve().parents[2] / "mjcf" / "humanoid.xml"
# m, pattern grid spacing (full run): 3.5 cm cells, 1730 garment vertices, ~40 ms per step
# on this machine (2.5 cm: 3180 vertices, ~100 ms per step with two runs on its two cores)
SPACING = 0.035
QUICK_SPACING = 0.05  # m (quick run)
# Step and solver (issue 15): the garments' bending is now partly implicit, so the step no longer has
# to resolve the explicit bending of 3.5 cm cells. Measured on the quick scene (cotton jersey, one
# core, the other busy): Newton 26 ms per 1 ms step (0.04x real time), 32 ms per 4 ms step; CG 14 ms
# per 4 ms step (0.28x), its constraint stage 6 ms against Newton's 24 (the Hessian of the
# implicit flex metric). At 4 ms the quick run stayed stable with the same penetration (<= 1 mm).
# Full (1730 vertices), five presets: stable, 27-43 ms per 4 ms step (0.09-0.15x real time);
# polyester satin's largest distance from the body 17.7 / 16.8 / 17.6 cm at 1 / 2 / 4 ms, so the step
# is not what sets it.
BODY_TIMESTEP = 4e-3
SOLVERS = {"cg": mujoco.mjtSolver.mjSOL_CG, "newton": mujoco.mjtSolver.mjSOL_NEWTON}
BODY_SOLVER = "cg"
SETTLE_S = 1.0  # s of sewing and settling with the body at rest; the checks start after it
QUICK_SECONDS = 2.0  # s: the quick run stops after the arms come down
FRAME_S = 1.0 / 30  # s between recorded frames
# Rerun's Capsules3D run along +z; each capsule is turned from it onto its geom's axis.
UP = np.array([0.0, 0.0, 1.0])
PENETRATION_TARGET = 0.01  # m
DISTANCE_TARGET = 0.15  # m
# Seams: connect equalities, critically damped, whose time constant falls geometrically from
# SEAM_SOLREF[0] to SEAM_TIME_CONSTANT_SEWN over SEAM_TIGHTEN_S. Soft at first (50 ms), so the
# panels meet without a jolt (MuJoCo's default 20 ms closes 0.3 m gaps violently); then 20 ms,
# softer than the capsule contacts (5 ms, mjcf/humanoid.xml): at 50 ms a constraint on a vertex of
# 0.3 g pulls with millinewtons, the cloth's tension holds seams open against the body and the
# shirt slides off; stiffer than the contacts (2 ms against 20 ms) the seams won and pulled seam
# vertices 2 cm into the shins (measured on the quick panels).
SEAM_SOLREF = (0.05, 1.0)
SEAM_TIME_CONSTANT_SEWN = 0.02
SEAM_TIGHTEN_S = (0.3, 0.8)
WAIST_PIN_HALF_WIDTH = 0.12  # m

# Panel placement (m): the planes x = ±d of the front and back panels.
SHIRT_DEPTH = 0.16
PANTS_DEPTH = 0.14
# Patterns as unions of rectangles (y0, y1, z0, z1) in m, in the panel plane (y left, z up).
# The shirt's torso is 0.49-0.50 m wide on the 2.5, 3.5 and 5 cm grids (cells whose centre lies
# inside): about 1 m around, the chest's girth (chest and torso capsules); at 1.12 m around (the
# 3.5 cm grid of a ±0.27 m pattern) the loose sides swung 25 cm out in the torso twist. Cut
# higher than the shoulders (z 1.60) so the shoulder seams close above the body.
SHIRT_PATTERN = ((-0.26, 0.26, 0.96, 1.60), (-0.50, 0.50, 1.33, 1.56))
SHIRT_NECK_HALF_WIDTH = 0.11
PANTS_PATTERN = ((-0.26, 0.26, 0.14, 1.00),)
PANTS_CROTCH = 0.80  # below it the legs are apart (a gap of one grid cell centred on y = 0)

# Scripted motion: keyframes (time s, joint targets rad or m); joints not named are at 0.
_ARMS_DOWN = {"l_shoulder": -math.radians(60), "r_shoulder": -math.radians(60),
              "l_elbow": math.radians(30), "r_elbow": math.radians(30)}
# A half squat: at 90° knees the thigh and shin capsules overlap behind the knee and pinch the
# pants' cloth inside them (a real leg squeezes it out; capsules cannot).
_SQUAT = {"root_z": -0.10, "l_hip": -math.radians(35), "r_hip": -math.radians(35), "l_knee": math.radians(60),
          "r_knee": math.radians(60)}
# Arms up 30° above horizontal, a ±20° twist at most 20° per second and a half squat: further or
# faster, the capsules overlapping at the shoulder and the hip pinch the cloth over 1 cm inside
# them and the shirt's sides swing out past 15 cm (measured on the 3.5 cm panels).
MOTION = ((0.0, {}), (1.0, {}), (2.0, _ARMS_DOWN),
          (3.0, {"l_shoulder": math.radians(30), "r_shoulder": math.radians(30)}), (3.5, {}),
          (4.5, {"abdomen": math.radians(20)}), (5.5, {"abdomen": -math.radians(20)}), (6.5, {}),
          (7.5, _SQUAT), (8.5, {}))


def motion_targets(t: float) -> dict[str, float]:
    """Joint targets at time ``t`` (s): cosine easing between the keyframes of :data:`MOTION`."""
    for (t0, a), (t1, b) in zip(MOTION, MOTION[1:]):
        if t <= t1:
            s = 0.5 - 0.5 * math.cos(math.pi * min(max((t - t0) / (t1 - t0), 0.0), 1.0))
            return {k: (1 - s) * a.get(k, 0.0) + s * b.get(k, 0.0) for k in set(a) | set(b)}
    return dict(MOTION[-1][1])


def seam_time_constant(t: float) -> float:
    """The seams' solref time constant (s) at time ``t`` (s): see :data:`SEAM_TIGHTEN_S`."""
    start, end = SEAM_TIGHTEN_S
    s = min(max((t - start) / (end - start), 0.0), 1.0)
    return SEAM_SOLREF[0] * (SEAM_TIME_CONSTANT_SEWN / SEAM_SOLREF[0]) ** s


def garment_panel(kind: str, spacing: float) -> tuple[trimesh.Trimesh, np.ndarray]:
    """A garment's pattern in its plane: a ``trimesh.Trimesh`` with vertices ``(0, y, z)`` (m) on
    a regular grid of ``spacing`` (cells kept whose centre lies inside the pattern, grid lines at
    multiples of ``spacing``) and a mask ``(n,)`` of the seam vertices (boundary vertices not on
    an opening)."""
    rects = SHIRT_PATTERN if kind == "shirt" else PANTS_PATTERN
    y0, y1 = min(r[0] for r in rects), max(r[1] for r in rects)
    z0, z1 = min(r[2] for r in rects), max(r[3] for r in rects)
    # The pants' grid is offset by half a cell so that one column of cells is centred on y = 0:
    # removing it below the crotch parts the legs with inseams at |y| = spacing / 2, inside the gap
    # between the thighs.
    offset = 0.5 * spacing if kind == "pants" else 0.0
    iy = np.arange(math.floor((y0 - offset) / spacing), math.ceil((y1 - offset) / spacing) + 1)
    iz = np.arange(math.floor(z0 / spacing), math.ceil(z1 / spacing) + 1)
    ny, nz = len(iy), len(iz)
    y, z = np.meshgrid(iy * spacing + offset, iz * spacing, indexing="ij")
    cy, cz = 0.5 * (y[:-1, :-1] + y[1:, 1:]), 0.5 * (z[:-1, :-1] + z[1:, 1:])
    inside = np.zeros(cy.shape, bool)
    for a, b, c, d in rects:
        inside |= (cy > a) & (cy < b) & (cz > c) & (cz < d)
    if kind == "pants":
        inside &= ~((np.abs(cy) < 0.5 * spacing) & (cz < PANTS_CROTCH))
    i, j = np.nonzero(inside)
    v00 = i * nz + j
    faces = np.concatenate([np.stack([v00, v00 + nz, v00 + nz + 1], 1), np.stack([v00, v00 + nz + 1, v00 + 1], 1)])
    vertices = np.column_stack([np.zeros(ny * nz), y.ravel(), z.ravel()])
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    mesh.remove_unreferenced_vertices()
    boundary_edges = mesh.edges_sorted[trimesh.grouping.group_rows(mesh.edges_sorted, require_count=1)]
    boundary = np.zeros(len(mesh.vertices), bool)
    boundary[boundary_edges.ravel()] = True
    py, pz = mesh.vertices[:, 1], mesh.vertices[:, 2]
    eps = 1e-9
    top, bottom, side = pz.max(), pz.min(), np.abs(py).max()
    if kind == "shirt":
        torso_side = np.abs(py[pz < pz.min() + 0.5 * spacing]).max()
        sleeve_low = pz[np.abs(py) > side - eps].min()
        opening = ((pz < bottom + eps) & (np.abs(py) < torso_side - eps)) \
            | ((np.abs(py) > side - eps) & (pz > sleeve_low + eps) & (pz < top - eps)) \
            | ((pz > top - eps) & (np.abs(py) < SHIRT_NECK_HALF_WIDTH - eps))
    else:
        inner = np.abs(py[pz < bottom + eps]).min()
        opening = ((pz > top - eps) & (np.abs(py) < side - eps)) \
            | ((pz < bottom + eps) & (np.abs(py) > inner + eps) & (np.abs(py) < side - eps))
    return mesh, boundary & ~opening


def build_body_scene(material_shirt: ClothMaterial, material_pants: ClothMaterial, *, spacing: float = SPACING,
                     timestep: float = BODY_TIMESTEP, solver: str = BODY_SOLVER) -> tuple[mujoco.MjSpec, dict]:
    """The humanoid with both garments (see the module docstring), stepped at ``timestep`` (s) by
    MuJoCo's ``solver`` (``"cg"`` or ``"newton"``). Returns the spec and, per garment, its panel
    flex names and vertex counts."""
    if solver not in SOLVERS:
        raise ValueError(f"unknown solver {solver!r}; solvers: {', '.join(SOLVERS)}")
    spec = mujoco.MjSpec.from_file(str(HUMANOID))
    spec.option.timestep = timestep
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_DISCRETE
    spec.option.solver = SOLVERS[solver]
    spec.worldbody.add_light(pos=[0, 0, 4], dir=[0, 0, -1], type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL)
    garments = {}
    for kind, material, depth in (("shirt", material_shirt, SHIRT_DEPTH), ("pants", material_pants, PANTS_DEPTH)):
        mesh, seam = garment_panel(kind, spacing)
        base = np.asarray(mesh.vertices)
        faces = np.asarray(mesh.faces)
        for side, sign in (("front", 1.0), ("back", -1.0)):
            name = f"{kind}_{side}"
            points = base + [sign * depth, 0.0, 0.0]
            # Opposite orientations so both panels' normals point away from the body once sewn.
            add_cloth_flex(spec, name, points, faces if sign > 0 else faces[:, ::-1], material, damping=DEFAULT_DAMPING,
                           friction=DEFAULT_FRICTION, contype=1, conaffinity=0)
            for v in np.flatnonzero(seam):
                spec.body(f"{name}_{v}").add_site(name=f"{name}_seam_{v}", size=[FLEX_RADIUS] * 3)
            if kind == "pants":
                waist = np.flatnonzero((base[:, 2] > base[:, 2].max() - 1e-9)
                                       & (np.abs(base[:, 1]) < WAIST_PIN_HALF_WIDTH))
                for v in waist:
                    eq = spec.add_equality(name=f"{name}_belt_{v}", type=mujoco.mjtEq.mjEQ_CONNECT,
                                           objtype=mujoco.mjtObj.mjOBJ_BODY, name1=f"{name}_{v}", name2="pelvis")
                    eq.data[:3] = 0.0
        for v in np.flatnonzero(seam):
            eq = spec.add_equality(name=f"{kind}_seam_{v}", type=mujoco.mjtEq.mjEQ_CONNECT,
                                   objtype=mujoco.mjtObj.mjOBJ_SITE, name1=f"{kind}_front_seam_{v}",
                                   name2=f"{kind}_back_seam_{v}")
            eq.solref = list(SEAM_SOLREF)
        garments[kind] = {"flexes": [f"{kind}_front", f"{kind}_back"], "vertices": 2 * len(base),
                          "triangles": 2 * len(faces), "seams": int(seam.sum())}
    return spec, garments


def _capsules(model: mujoco.MjModel, data: mujoco.MjData, geoms: np.ndarray):
    """Capsule end points ``a, b (G, 3)`` and radii ``(G,)`` (m)."""
    axis = data.geom_xmat[geoms][:, [2, 5, 8]]
    half = model.geom_size[geoms, 1][:, None]
    centre = data.geom_xpos[geoms]
    return centre - half * axis, centre + half * axis, model.geom_size[geoms, 0]


def surface_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """Signed distance ``(N,)`` (m) of each point from the union of capsules (negative inside)."""
    ab = b - a
    t = np.clip(np.einsum("ngk,gk->ng", points[:, None, :] - a[None], ab) / np.einsum("gk,gk->g", ab, ab), 0, 1)
    nearest = a[None] + t[..., None] * ab[None]
    return (np.linalg.norm(points[:, None, :] - nearest, axis=2) - radius[None]).min(axis=1)


@dataclass(frozen=True)
class BodyResult(SceneResult):
    """The full-body run: the materials, the panel spacing (m), time step, simulated time (s) and
    steps taken, the garments' panels and seams, MuJoCo's bad-QACC warnings, whether a position
    went non-finite, ``stable`` (neither, and every step taken), the largest penetration into and
    distance from the body (m) after :data:`SETTLE_S` and where the farthest vertex was, the
    targets, ``passed`` (stable and both within target), wall time (s), ms per step, and the
    recording's path if one was written."""

    material_shirt: str
    material_pants: str
    quick: bool
    spacing_m: float
    timestep_s: float
    simulated_s: float
    steps: int
    garments: dict
    bad_qacc: int
    nonfinite: bool
    stable: bool
    max_penetration_m: float
    max_distance_m: float
    farthest_vertex: dict | None
    penetration_target_m: float
    distance_target_m: float
    passed: bool
    wall_time_s: float
    ms_per_step: float
    checks_from_s: float
    recording: str | None = field(default=None, metadata=OPTIONAL)


def run_body(material_shirt, material_pants=None, *, quick: bool = False, recording_path=None,
             progress=None, timestep: float = BODY_TIMESTEP, solver: str = BODY_SOLVER) -> BodyResult:
    """Run the full-body scene (module docstring) and return its :class:`BodyResult`.

    Args:
        material_shirt: a :class:`~yarnfit.mujoco.scenes.ClothMaterial` or a material file.
        material_pants: the same for the pants; default the shirt's material.
        quick: coarse panels (:data:`QUICK_SPACING`) and the motion cut at :data:`QUICK_SECONDS`.
        recording_path: the ``.rrd`` file to write (directories created), or None.
        progress: called as ``progress(message)`` once per simulated second.
        timestep: Δt (s).
        solver: MuJoCo's constraint solver, ``"cg"`` or ``"newton"``.
    """
    shirt = material_shirt if isinstance(material_shirt, ClothMaterial) else ClothMaterial.from_file(material_shirt)
    pants = shirt if material_pants is None else (
        material_pants if isinstance(material_pants, ClothMaterial) else ClothMaterial.from_file(material_pants))
    spacing = QUICK_SPACING if quick else SPACING
    seconds = QUICK_SECONDS if quick else MOTION[-1][0]
    spec, garments = build_body_scene(shirt, pants, spacing=spacing, timestep=timestep, solver=solver)
    model = compile_quietly(spec)
    data = mujoco.MjData(model)
    actuators = {model.actuator(i).name: i for i in range(model.nu)}
    seams = np.array([i for i in range(model.neq) if "_seam_" in model.equality(i).name])
    geoms = np.array([g for g in range(model.ngeom) if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_CAPSULE])
    geom_names = [model.geom(g).name for g in geoms]
    vert = {kind: np.concatenate([np.arange(model.flex_vertadr[_flex_id(model, f)],
                                            model.flex_vertadr[_flex_id(model, f)] + model.flex_vertnum[_flex_id(model, f)])
                                  for f in g["flexes"]]) for kind, g in garments.items()}
    recording = _BodyRecording(recording_path, shirt.name, model, garments, geom_names) if recording_path else None

    steps = round(seconds / model.opt.timestep)
    frame_every = max(1, round(FRAME_S / model.opt.timestep))
    warning = int(mujoco.mjtWarning.mjWARN_BADQACC)
    max_pen, max_dist, nonfinite, taken = 0.0, 0.0, False, 0
    series = []
    farthest = None
    elapsed = 0.0
    for step in range(steps + 1):
        t = step * model.opt.timestep
        if step % frame_every == 0 or step == steps:
            mujoco.mj_forward(model, data)
            points = data.flexvert_xpos
            if not np.all(np.isfinite(points)):
                nonfinite = True
                break
            a, b, r = _capsules(model, data, geoms)
            signed = {kind: surface_distance(points[idx], a, b, r) for kind, idx in vert.items()}
            pen = max(float(max(0.0, -s.min())) for s in signed.values())
            dist = max(float(s.max()) for s in signed.values())
            if t >= SETTLE_S - 1e-12:
                max_pen = max(max_pen, pen)
                if dist > max_dist:
                    kind = max(signed, key=lambda k: signed[k].max())
                    farthest = {"garment": kind, "time_s": t,
                                "position_m": points[vert[kind][int(signed[kind].argmax())]].tolist()}
                max_dist = max(max_dist, dist)
            series.append((t, pen, dist))
            if recording:
                recording.frame(t, {k: points[idx] for k, idx in vert.items()}, a, r, b, pen, dist)
        if step == steps:
            break
        if progress and step % 1000 == 0:
            progress(f"body: {t:.1f}/{seconds:.1f} s simulated")
        model.eq_solref[seams, 0] = seam_time_constant(t)
        for joint, value in motion_targets(t + model.opt.timestep).items():
            data.ctrl[actuators[joint]] = value
        start = time.perf_counter()
        mujoco.mj_step(model, data)
        elapsed += time.perf_counter() - start
        taken += 1
        if data.warning[warning].number > 0 or not np.all(np.isfinite(data.qpos)):
            nonfinite = nonfinite or not np.all(np.isfinite(data.qpos))
            break
    bad_qacc = int(data.warning[warning].number)
    stable = bad_qacc == 0 and not nonfinite and taken == steps
    result = BodyResult(
        material_shirt=shirt.name,
        material_pants=pants.name,
        quick=bool(quick),
        spacing_m=spacing,
        timestep_s=float(model.opt.timestep),
        simulated_s=taken * float(model.opt.timestep),
        steps=taken,
        garments=garments,
        bad_qacc=bad_qacc,
        nonfinite=bool(nonfinite),
        stable=bool(stable),
        max_penetration_m=max_pen,
        max_distance_m=max_dist,
        farthest_vertex=farthest,
        penetration_target_m=PENETRATION_TARGET,
        distance_target_m=DISTANCE_TARGET,
        passed=bool(stable and max_pen < PENETRATION_TARGET and max_dist < DISTANCE_TARGET),
        wall_time_s=elapsed,
        ms_per_step=1e3 * elapsed / max(taken, 1),
        checks_from_s=SETTLE_S,
    )
    if recording:
        recording.finish(result)
        result = replace(result, recording=str(recording_path))
    return result


class _BodyRecording(Recording):
    """The ``.rrd`` file of one run (paths in the module docstring)."""

    def __init__(self, path, name: str, model: mujoco.MjModel, garments: dict, geom_names: list[str]) -> None:
        layout = rrb.Blueprint(
            rrb.Horizontal(
                rrb.Spatial3DView(origin="body", name="body"),
                rrb.Vertical(
                    rrb.TimeSeriesView(origin="body/plots/penetration", name="penetration (m)"),
                    rrb.TimeSeriesView(origin="body/plots/distance", name="distance (m)"),
                    rrb.TextDocumentView(origin="body/summary", name="summary"),
                ),
                column_shares=[3, 1],
            ),
            *folded_panels("sim_time"))
        super().__init__(f"body: {name}", path, layout, "body")
        colors = {"shirt": [60, 110, 200], "pants": [70, 70, 80]}
        for kind, g in garments.items():
            triangles, offset = [], 0
            for f in g["flexes"]:
                fid = _flex_id(model, f)
                adr, num = model.flex_elemdataadr[fid], model.flex_elemnum[fid]
                triangles.append(model.flex_elem[adr:adr + 3 * num].reshape(-1, 3) + offset)
                offset += model.flex_vertnum[fid]
            self.stream.log(f"body/cloth/{kind}", rr.Mesh3D.from_fields(
                triangle_indices=np.concatenate(triangles), albedo_factor=colors[kind]), static=True)
        self.geom_names = geom_names

    def frame(self, t, garments, a, radius, b, pen, dist) -> None:
        self.stream.set_time("sim_time", duration=t)
        for kind, points in garments.items():
            self.stream.log(f"body/cloth/{kind}", rr.Mesh3D.from_fields(vertex_positions=points))
        for g, name in enumerate(self.geom_names):
            axis = b[g] - a[g]
            length = float(np.linalg.norm(axis))
            quat = quaternion_between(UP, axis / length if length > 0 else UP)
            self.stream.log(f"body/bodies/{name}", rr.Capsules3D(lengths=[length], radii=[radius[g]], translations=[a[g]],
                                                               quaternions=[rr.Quaternion(xyzw=xyzw(quat))]))
        self.stream.log("body/plots/penetration", rr.Scalars(pen))
        self.stream.log("body/plots/distance", rr.Scalars(dist))

    def finish(self, result: BodyResult) -> None:
        rows = [("stable", result.stable), ("bad QACC warnings", result.bad_qacc),
                ("max penetration (m)", f"{result.max_penetration_m:.4g} (target < {PENETRATION_TARGET:g})"),
                ("max distance (m)", f"{result.max_distance_m:.4g} (target < {DISTANCE_TARGET:g})"),
                ("simulated (s)", f"{result.simulated_s:.3g}"), ("ms/step", f"{result.ms_per_step:.3g}"),
                ("wall time (s)", f"{result.wall_time_s:.3g}"), ("shirt", result.material_shirt),
                ("pants", result.material_pants), ("panel grid spacing (m)", result.spacing_m)]
        self.log_markdown("body/summary", "# full body\n\n" + markdown_table(rows), static=True)
        self.close()


def _flex_id(model: mujoco.MjModel, name: str) -> int:
    return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_FLEX, name)
