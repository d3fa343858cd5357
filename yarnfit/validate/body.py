"""Full-body scene (issue 6, issue 15): a T-shirt and pants of fitted materials on a humanoid whose
joints follow a scripted motion.

The body is ``mjcf/humanoid.xml`` (capsules, position actuators, gravity compensated; see the
file's comments for joints and motion). Each garment is **one flex sewn from 2D panels**
(:mod:`yarnfit.mujoco.garment`), as a tailor makes it: a front and a back panel cut from the same
pattern (a union of rectangles on a grid of spacing :data:`SPACING` / :data:`QUICK_SPACING`, each
cell split by both diagonals around a centre vertex: criss-cross cells do not lock, plugins/README.md),
the back one turned over, weft horizontal in both. Seams are **shared vertices**: each seam vertex
of the front panel is the back panel's vertex at the same pattern point. The ``yarnfit.shell``
plugin takes each triangle's rest from its panel's pattern (``rest="texcoord"``), so the garment is
sewn by its rest state, with no equality constraints and no prestress from the construction.

Where a garment starts: its two panels are laid flat in the planes ``x = ±d`` around the body in
its T-pose rest (:data:`SHIRT_DEPTH`, :data:`PANTS_DEPTH`), each seam vertex midway between them; the
cells at the seams are then stretched several times their rest size, far more than the fitted
material can take in one explicit step. :func:`sew_on` pulls them together first with MuJoCo's own
isotropic elasticity (:func:`~yarnfit.mujoco.split.isotropic_fallback`'s material, its rest the
pattern's, integrated implicitly so any strain is stable, heavily damped) for :data:`SEW_S` with
the body still; the garment then starts from where that left it, strains of a few per cent (the
sewing's result is in the run's summary).

* Shirt: a T-shaped pattern (torso and sleeves), sewn along the sides, under the sleeves and over
  the shoulders and sleeves; open at the hem, the neck and the sleeve ends.
* Pants: a Π-shaped pattern (waist, two legs apart below the crotch), sewn along the outer sides,
  the inseams and the crotch; open at the waist and the leg ends. The waistband's middle (|y| <
  :data:`WAIST_PIN_HALF_WIDTH`) is held on the pelvis by ``connect`` equalities (a belt).

Checks (after :data:`SETTLE_S`): MuJoCo's bad-QACC warning count and non-finite positions;
penetration = largest depth of a garment vertex inside any capsule (m; target
:data:`PENETRATION_TARGET`); distance = largest distance of a garment vertex from the body
surface, i.e. from its nearest capsule (m; target :data:`DISTANCE_TARGET`); wall time, ms/step.
``native=True`` runs the same scene with MuJoCo's native isotropic elasticity alone (no plugin),
for the cost comparison.

Recording (``recording_path``, e.g. ``logs/<material>/body.rrd``; one ``RecordingStream``,
application id ``"yarnfit"``), timeline ``sim_time`` (s), one frame every :data:`FRAME_S`:

- ``body``: ``ViewCoordinates`` right-handed, z up (static).
- ``body/cloth/shirt``, ``body/cloth/pants``: ``Mesh3D``, triangles and colour static, vertex
  positions (m) per frame (the garment's flex, front and back panels in one mesh).
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
from ..mujoco.garment import Garment, Panel, Seam, sew, use_pattern_rest
from ..mujoco.scenes import ClothMaterial, add_cloth_flex, compile_quietly, solver_enum
from ..record import Recording, folded_panels, markdown_table
from . import OPTIONAL, SceneResult

__all__ = ["BodyResult", "HUMANOID", "MOTION", "build_body_scene", "compile_body_scene", "fold_angles",
           "garment_pattern", "motion_targets", "run_body", "sew_on", "sewn_garment"]

HUMANOID = Path(__file__).resolve().parents[2] / "mjcf" / "humanoid.xml"
# m, pattern grid spacing: criss-cross cells, so vertices (corners and centres) lie 0.7 spacing apart.
# Full: 1420 garment vertices (the earlier one-diagonal 3.5 cm panels had 1730); quick: 690.
SPACING = 0.05
QUICK_SPACING = 0.07  # m (quick run)
# Step and solver (issue 15): the garments' bending is partly implicit, so the step need not resolve
# the explicit bending of the cells. Measured before the one-flex garments (quick scene, cotton
# jersey): Newton 26 ms per 1 ms step, 32 ms per 4 ms step; CG 14 ms per 4 ms step, its constraint
# stage 6 ms against Newton's 24 (the Hessian of the implicit flex metric).
BODY_TIMESTEP = 4e-3
BODY_SOLVER = "cg"
# MuJoCo's solver tolerance (its default 1e-8). Measured on the full scene, cotton twill: CG ran 67
# iterations a step on average (its cap of 100 often), the constraint stage 11 of 23 ms; at 1e-6 and
# 1e-5, 36 and 23 iterations, 16.9 and 15.1 ms a step, and the same run to the figures' digits
# (penetration 3.83 / 3.83 / 3.82 mm, distance 9.7 cm all three, creases 121 and 86-87 hinges).
# At 1e-4 against 1e-5, one-flex garments, all five presets, full run in one session: 3-10 % less
# stepping time, penetration within 0.05 mm (twill 1.38 / 1.39, satin 2.59 / 2.61), distance the
# same to 1 mm, creases within 3 hinges of 24-129, largest folds within 1.2°.
BODY_TOLERANCE = 1e-4
SETTLE_S = 1.0  # s of settling with the body at rest; the checks start after it
QUICK_SECONDS = 2.0  # s: the quick run stops after the arms come down
FRAME_S = 1.0 / 30  # s between recorded frames
# Rerun's Capsules3D run along +z; each capsule is turned from it onto its geom's axis.
UP = np.array([0.0, 0.0, 1.0])
PENETRATION_TARGET = 0.005  # m: no vertex more than 5 mm inside a body geom (issue 15)
# The garments' contact time constant and damping ratio: the humanoid's capsules' (mjcf/humanoid.xml,
# 5 ms). MuJoCo mixes a contact's solref from both sides (solmix 1 each: the mean), so with the
# flex's default 20 ms the contacts ran at 12.5 ms, not the body's 5. Measured on the cotton twill
# with its ridge membrane (session 36): penetration 7.86 mm at 12.5 ms against 1.25 mm at 5 ms; at
# 12.5 ms it grew with the split's built-in stiffness (E t 37, 72, 106, 160 kN/m: 4.05, 5.14, 6.35,
# 7.86 mm; under the discrete integrator the contacts are solved in the metric M + h² K).
GARMENT_CONTACT_SOLREF = (0.005, 1.0)
DISTANCE_TARGET = 0.15  # m
# Creases: a hinge away from the seams folded beyond this (degrees) between its two triangles. A
# garment lying smooth on the body folds its hinges by a few degrees per cell; a crease or a
# wrinkle's ridge by tens (cotton jersey at 5 cm cells: 60-90 such hinges in the shirt after the
# arms come down, p99 fold 90-100°).
CREASE_ANGLE_DEG = 60.0
WAIST_PIN_HALF_WIDTH = 0.12  # m
# Sewing (sew_on): time, and the damping time of MuJoCo's native elasticity while sewing, twenty
# times the material's so the panels close without swinging. Overdamped modes relax with that time
# constant: 0.1 s left the seams' cells 30-50 % stretched after 0.3 s, 0.02 s 4-5 % (shirt, cotton
# jersey, 7 cm cells; 0.6 s no better).
SEW_S = 0.3
SEW_DAMPING = 0.02  # s

# Panel placement (m): the planes x = ±d of the front and back panels.
SHIRT_DEPTH = 0.16
PANTS_DEPTH = 0.14
# Patterns as unions of rectangles (y0, y1, z0, z1) in m, in the panel plane (y left, z up).
# The shirt's torso is 0.50 m wide: 1 m around, the chest's girth (chest and torso capsules); at
# 1.12 m around the loose sides swung 25 cm out in the torso twist. Cut higher than the shoulders
# (z 1.60) so the shoulder seams close above the body.
SHIRT_PATTERN = ((-0.25, 0.25, 0.96, 1.60), (-0.50, 0.50, 1.33, 1.56))
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


def garment_pattern(kind: str, spacing: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A garment's pattern (``kind`` ``"shirt"`` or ``"pants"``): ``points (n, 2)`` (y, z) in m,
    the cells of a grid of ``spacing`` whose centre lies inside the pattern (grid lines at
    multiples of ``spacing``), each split by both diagonals around a centre vertex;
    ``triangles (m, 3)`` counter-clockwise in (y, z); and a mask ``(n,)`` of the seam vertices
    (boundary vertices not on an opening)."""
    if kind not in ("shirt", "pants"):
        raise ValueError(f"unknown garment {kind!r}; garments: shirt, pants")
    rects = SHIRT_PATTERN if kind == "shirt" else PANTS_PATTERN
    y0, y1 = min(r[0] for r in rects), max(r[1] for r in rects)
    z0, z1 = min(r[2] for r in rects), max(r[3] for r in rects)
    # The pants' grid is offset by half a cell so that one column of cells is centred on y = 0:
    # removing it below the crotch parts the legs with inseams at |y| = spacing / 2, inside the gap
    # between the thighs.
    offset = 0.5 * spacing if kind == "pants" else 0.0
    iy = np.arange(math.floor((y0 - offset) / spacing), math.ceil((y1 - offset) / spacing) + 1)
    iz = np.arange(math.floor(z0 / spacing), math.ceil(z1 / spacing) + 1)
    nz = len(iz)
    y, z = np.meshgrid(iy * spacing + offset, iz * spacing, indexing="ij")
    cy, cz = 0.5 * (y[:-1, :-1] + y[1:, 1:]), 0.5 * (z[:-1, :-1] + z[1:, 1:])
    inside = np.zeros(cy.shape, bool)
    for a, b, c, d in rects:
        inside |= (cy > a) & (cy < b) & (cz > c) & (cz < d)
    if kind == "pants":
        inside &= ~((np.abs(cy) < 0.5 * spacing) & (cz < PANTS_CROTCH))
    i, j = np.nonzero(inside)
    corners = np.column_stack([y.ravel(), z.ravel()])
    v00 = i * nz + j
    v10, v11, v01 = v00 + nz, v00 + nz + 1, v00 + 1
    centre = len(corners) + np.arange(len(i))
    triangles = np.concatenate([np.stack([v00, v10, centre], 1), np.stack([v10, v11, centre], 1),
                                np.stack([v11, v01, centre], 1), np.stack([v01, v00, centre], 1)])
    points = np.vstack([corners, np.column_stack([cy[i, j], cz[i, j]])])
    used = np.unique(triangles)
    remap = np.full(len(points), -1)
    remap[used] = np.arange(len(used))
    points, triangles = points[used], remap[triangles]
    mesh = trimesh.Trimesh(np.column_stack([np.zeros(len(points)), points]), triangles, process=False)
    boundary_edges = mesh.edges_sorted[trimesh.grouping.group_rows(mesh.edges_sorted, require_count=1)]
    boundary = np.zeros(len(points), bool)
    boundary[boundary_edges.ravel()] = True
    py, pz = points[:, 0], points[:, 1]
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
    return points, triangles, boundary & ~opening


def sewn_garment(kind: str, spacing: float) -> Garment:
    """The garment (:func:`garment_pattern`) as one mesh: the front panel in the plane
    ``x = +d``, the back one turned over in ``x = −d`` (both normals outward once closed), every
    seam vertex shared, midway between them. Weft horizontal (along the pattern's y) in both."""
    points, triangles, seam = garment_pattern(kind, spacing)
    depth = SHIRT_DEPTH if kind == "shirt" else PANTS_DEPTH
    front = Panel("front", points, triangles, np.column_stack([np.full(len(points), depth), points]))
    back = Panel("back", points, triangles[:, ::-1], np.column_stack([np.full(len(points), -depth), points]))
    seam_vertices = np.flatnonzero(seam)
    return sew([front, back], [Seam("front", seam_vertices, "back", seam_vertices)])


def build_body_scene(material_shirt: ClothMaterial, material_pants: ClothMaterial, *, spacing: float = SPACING,
                     timestep: float = BODY_TIMESTEP, solver: str = BODY_SOLVER, native: bool = False,
                     start: dict | None = None, damping: float = DEFAULT_DAMPING,
                     belt: bool = True, tolerance: float = BODY_TOLERANCE) -> tuple[mujoco.MjSpec, dict]:
    """The humanoid with both garments (see the module docstring), stepped at ``timestep`` (s) by
    MuJoCo's ``solver`` (``"cg"`` or ``"newton"``) to ``tolerance``; ``native``: MuJoCo's isotropic elasticity
    alone, no plugin. ``start`` maps ``"shirt"``/``"pants"`` to the garment's start positions
    ``(V, 3)`` (m; default the flat panels of :func:`sewn_garment`); ``belt``: hold the pants'
    waistband on the pelvis where it starts. Returns the spec and, per
    garment, its :class:`~yarnfit.mujoco.garment.Garment`, vertex, triangle and seam-vertex
    counts. Compile it with :func:`compile_body_scene`."""
    solver_code = solver_enum(solver)
    spec = mujoco.MjSpec.from_file(str(HUMANOID))
    spec.option.timestep = timestep
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_DISCRETE
    spec.option.solver = solver_code
    spec.option.tolerance = tolerance
    spec.worldbody.add_light(pos=[0, 0, 4], dir=[0, 0, -1], type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL)
    garments = {}
    for kind, material in (("shirt", material_shirt), ("pants", material_pants)):
        garment = sewn_garment(kind, spacing)
        points = garment.points if start is None else np.asarray(start[kind], float)
        if points.shape != garment.points.shape:
            raise ValueError(f"start[{kind!r}] must be {garment.points.shape}, got {points.shape}")
        flex = add_cloth_flex(spec, kind, points, garment.triangles, material, damping=damping,
                              friction=DEFAULT_FRICTION, contype=1, conaffinity=0, rest_uv=garment.corner_uv,
                              fallback=native)
        flex.solref = list(GARMENT_CONTACT_SOLREF)
        if kind == "pants" and belt:
            top = garment.points[:, 2].max()  # the flat panels' waistband (z is the pattern's)
            waist = np.flatnonzero((garment.points[:, 2] > top - 1e-9)
                                   & (np.abs(garment.points[:, 1]) < WAIST_PIN_HALF_WIDTH))
            for v in waist:
                eq = spec.add_equality(name=f"pants_belt_{v}", type=mujoco.mjtEq.mjEQ_CONNECT,
                                       objtype=mujoco.mjtObj.mjOBJ_BODY, name1=f"pants_{v}", name2="pelvis")
                eq.data[:3] = 0.0
        garments[kind] = {"garment": garment, "builtin": (flex.young, flex.poisson, flex.thickness),
                          "vertices": len(garment.points), "triangles": len(garment.triangles),
                          "seam_vertices": len(garment.seam_vertices)}
    return spec, garments


def compile_body_scene(spec: mujoco.MjSpec, garments: dict) -> mujoco.MjModel:
    """Compile :func:`build_body_scene`'s spec and give MuJoCo's built-in elasticity on each
    garment the pattern's rest (:func:`~yarnfit.mujoco.garment.use_pattern_rest`)."""
    model = compile_quietly(spec)
    for kind, g in garments.items():
        use_pattern_rest(model, kind, *g["builtin"])
    return model


def sew_on(material_shirt: ClothMaterial, material_pants: ClothMaterial, *, spacing: float = SPACING,
           timestep: float = BODY_TIMESTEP) -> tuple[dict, dict]:
    """Sew the garments around the body (module docstring): :data:`SEW_S` of MuJoCo's native
    elasticity, damping :data:`SEW_DAMPING`, from the flat panels, the body at rest, without
    gravity or the belt (the garments only close around the body; the run's belt then holds the
    waistband where the sewing left it). Returns the start positions per garment ``(V, 3)`` (m)
    and, per garment, the largest stretch and compression of a pattern edge at the end
    (``{"max_stretch": …, "max_compression": …}``, engineering strain). Raises ``RuntimeError`` if
    a position goes non-finite."""
    spec, garments = build_body_scene(material_shirt, material_pants, spacing=spacing, timestep=timestep,
                                      native=True, damping=SEW_DAMPING, belt=False)
    spec.option.gravity = [0.0, 0.0, 0.0]
    model = compile_body_scene(spec, garments)
    data = mujoco.MjData(model)
    for _ in range(round(SEW_S / timestep)):
        mujoco.mj_step(model, data)
    start, strain = {}, {}
    for kind, g in garments.items():
        f = _flex_id(model, kind)
        x = data.flexvert_xpos[model.flex_vertadr[f]:model.flex_vertadr[f] + model.flex_vertnum[f]].copy()
        if not np.all(np.isfinite(x)):
            raise RuntimeError(f"sewing the {kind} went non-finite")
        start[kind] = x
        edges = model.flex_edge[model.flex_edgeadr[f]:model.flex_edgeadr[f] + model.flex_edgenum[f]]
        rest = model.flexedge_length0[model.flex_edgeadr[f]:model.flex_edgeadr[f] + model.flex_edgenum[f]]
        e = np.linalg.norm(x[edges[:, 1]] - x[edges[:, 0]], axis=1) / rest - 1
        strain[kind] = {"max_stretch": float(e.max()), "max_compression": float(-e.min())}
    return start, strain


def _capsules(model: mujoco.MjModel, data: mujoco.MjData, geoms: np.ndarray):
    """Capsule end points ``a, b (G, 3)`` and radii ``(G,)`` (m)."""
    axis = data.geom_xmat[geoms][:, [2, 5, 8]]
    half = model.geom_size[geoms, 1][:, None]
    centre = data.geom_xpos[geoms]
    return centre - half * axis, centre + half * axis, model.geom_size[geoms, 0]


def fold_angles(points: np.ndarray, hinges: np.ndarray) -> np.ndarray:
    """Dihedral fold angle (rad, 0 = flat) across each hinge ``(H, 4)`` (edge v0, v1 and the two
    opposite vertices) of positions ``points (V, 3)``: the angle between its two triangles' normals."""
    edge = points[hinges[:, 1]] - points[hinges[:, 0]]
    n0 = np.cross(edge, points[hinges[:, 2]] - points[hinges[:, 0]])
    n1 = np.cross(points[hinges[:, 3]] - points[hinges[:, 0]], edge)
    cos = np.einsum("hi,hi->h", n0, n1) / (np.linalg.norm(n0, axis=1) * np.linalg.norm(n1, axis=1))
    return np.arccos(np.clip(cos, -1.0, 1.0))


def surface_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """Signed distance ``(N,)`` (m) of each point from the union of capsules (negative inside)."""
    ab = b - a
    t = np.clip(np.einsum("ngk,gk->ng", points[:, None, :] - a[None], ab) / np.einsum("gk,gk->g", ab, ab), 0, 1)
    nearest = a[None] + t[..., None] * ab[None]
    return (np.linalg.norm(points[:, None, :] - nearest, axis=2) - radius[None]).min(axis=1)


@dataclass(frozen=True)
class BodyResult(SceneResult):
    """The full-body run: the materials, the panel spacing (m), time step, simulated time (s) and
    steps taken, whether MuJoCo's native elasticity ran alone, the garments' vertex, triangle and
    seam-vertex counts, the sewing's largest stretch and compression of a pattern edge per garment
    and its wall time (s), the creases at the end (per garment the hinges away from the seams folded
    beyond :data:`CREASE_ANGLE_DEG` and the largest fold, degrees), MuJoCo's bad-QACC warnings,
    whether a position
    went non-finite, ``stable`` (neither, and every step taken), the largest penetration into and
    distance from the body (m) after :data:`SETTLE_S` and where the farthest vertex was, the
    targets, ``passed`` (stable and both within target), wall time (s), ms per step, and the
    recording's path if one was written."""

    material_shirt: str
    material_pants: str
    quick: bool
    native: bool
    spacing_m: float
    timestep_s: float
    simulated_s: float
    steps: int
    garments: dict
    sewing: dict
    sewing_wall_time_s: float
    creases: dict
    crease_angle_deg: float
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
             progress=None, timestep: float = BODY_TIMESTEP, solver: str = BODY_SOLVER,
             native: bool = False, tolerance: float = BODY_TOLERANCE) -> BodyResult:
    """Run the full-body scene (module docstring) and return its :class:`BodyResult`.

    Args:
        material_shirt: a :class:`~yarnfit.mujoco.scenes.ClothMaterial` or a material file.
        material_pants: the same for the pants; default the shirt's material.
        quick: coarse panels (:data:`QUICK_SPACING`) and the motion cut at :data:`QUICK_SECONDS`.
        recording_path: the ``.rrd`` file to write (directories created), or None.
        progress: called as ``progress(message)`` once per simulated second.
        timestep: Δt (s).
        solver: MuJoCo's constraint solver, ``"cg"`` or ``"newton"``.
        native: MuJoCo's native isotropic elasticity alone (no plugin), for comparison.
        tolerance: MuJoCo's solver tolerance.
    """
    shirt = material_shirt if isinstance(material_shirt, ClothMaterial) else ClothMaterial.from_file(material_shirt)
    pants = shirt if material_pants is None else (
        material_pants if isinstance(material_pants, ClothMaterial) else ClothMaterial.from_file(material_pants))
    spacing = QUICK_SPACING if quick else SPACING
    seconds = QUICK_SECONDS if quick else MOTION[-1][0]
    if progress:
        progress("body: sewing the garments on")
    sew_start = time.perf_counter()
    start, sewing = sew_on(shirt, pants, spacing=spacing, timestep=timestep)
    sewing_s = time.perf_counter() - sew_start
    spec, garments = build_body_scene(shirt, pants, spacing=spacing, timestep=timestep, solver=solver, native=native,
                                      start=start, tolerance=tolerance)
    model = compile_body_scene(spec, garments)
    data = mujoco.MjData(model)
    actuators = {model.actuator(i).name: i for i in range(model.nu)}
    geoms = np.array([g for g in range(model.ngeom) if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_CAPSULE])
    geom_names = [model.geom(g).name for g in geoms]
    vert = {kind: model.flex_vertadr[_flex_id(model, kind)] + np.arange(model.flex_vertnum[_flex_id(model, kind)])
            for kind in garments}
    hinges = {kind: _inner_hinges(model, kind, g["garment"].seam_vertices) for kind, g in garments.items()}
    recording = _BodyRecording(recording_path, shirt.name, model, garments, geom_names) if recording_path else None

    steps = round(seconds / model.opt.timestep)
    frame_every = max(1, round(FRAME_S / model.opt.timestep))
    warning = int(mujoco.mjtWarning.mjWARN_BADQACC)
    max_pen, max_dist, nonfinite, taken = 0.0, 0.0, False, 0
    series = []
    last_frame = None  # positions at the last frame read: the creases are counted there
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
            last_frame = points.copy()
            if recording:
                recording.frame(t, {k: points[idx] for k, idx in vert.items()}, a, r, b, pen, dist)
        if step == steps:
            break
        if progress and step % 1000 == 0:
            progress(f"body: {t:.1f}/{seconds:.1f} s simulated")
        for joint, value in motion_targets(t + model.opt.timestep).items():
            data.ctrl[actuators[joint]] = value
        start = time.perf_counter()
        mujoco.mj_step(model, data)
        elapsed += time.perf_counter() - start
        taken += 1
        if data.warning[warning].number > 0 or not np.all(np.isfinite(data.qpos)):
            nonfinite = nonfinite or not np.all(np.isfinite(data.qpos))
            break
    folds = {} if last_frame is None else {kind: np.degrees(fold_angles(last_frame[vert[kind]], h))
                                           for kind, h in hinges.items()}
    bad_qacc = int(data.warning[warning].number)
    stable = bad_qacc == 0 and not nonfinite and taken == steps
    result = BodyResult(
        material_shirt=shirt.name,
        material_pants=pants.name,
        quick=bool(quick),
        native=bool(native),
        spacing_m=spacing,
        timestep_s=float(model.opt.timestep),
        simulated_s=taken * float(model.opt.timestep),
        steps=taken,
        garments={kind: {k: v for k, v in g.items() if k not in ("garment", "builtin")} for kind, g in garments.items()},
        sewing=sewing,
        creases={kind: {"hinges": int((f > CREASE_ANGLE_DEG).sum()), "max_fold_deg": float(f.max())}
                 for kind, f in folds.items()},
        crease_angle_deg=CREASE_ANGLE_DEG,
        sewing_wall_time_s=sewing_s,
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
        for kind in garments:
            fid = _flex_id(model, kind)
            adr, num = model.flex_elemdataadr[fid], model.flex_elemnum[fid]
            self.stream.log(f"body/cloth/{kind}", rr.Mesh3D.from_fields(
                triangle_indices=model.flex_elem[adr:adr + 3 * num].reshape(-1, 3), albedo_factor=colors[kind]),
                static=True)
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
                ("pants", result.material_pants), ("panel grid spacing (m)", result.spacing_m),
                ("native elasticity only", result.native),
                *((f"{kind} creases: hinges folded > {CREASE_ANGLE_DEG:g}° / largest fold (°)",
                   f"{c['hinges']} / {c['max_fold_deg']:.0f}") for kind, c in result.creases.items()),
                *((f"{kind} after sewing: largest stretch / compression", f"{s['max_stretch']:.3g} / "
                   f"{s['max_compression']:.3g}") for kind, s in result.sewing.items())]
        self.log_markdown("body/summary", "# full body\n\n" + markdown_table(rows), static=True)
        self.close()


def _inner_hinges(model: mujoco.MjModel, kind: str, seam_vertices: np.ndarray) -> np.ndarray:
    """The hinges ``(H, 4)`` (flex-local edge v0, v1 and flaps) of garment ``kind`` whose edge is not
    on a seam (a seam folds where two panels meet, by construction)."""
    f = _flex_id(model, kind)
    adr, num = model.flex_edgeadr[f], model.flex_edgenum[f]
    edges, flaps = model.flex_edge[adr:adr + num], model.flex_edgeflap[adr:adr + num]
    on_seam = np.isin(edges, seam_vertices).all(axis=1)
    return np.column_stack([edges, flaps])[(flaps[:, 1] >= 0) & ~on_seam]


def _flex_id(model: mujoco.MjModel, name: str) -> int:
    return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_FLEX, name)
