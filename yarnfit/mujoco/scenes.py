"""MuJoCo scenes for a fitted material, built with ``mujoco.MjSpec``.

A scene is one square (or strip) of cloth as a 2D flex built the way MuJoCo's ``<flexcomp
type="grid">`` builds it: one body per free vertex with three world-axis slide joints, pinned
vertices on the world or a clamp body, triangles ``(v00, v10, v11), (v00, v11, v01)`` per grid
cell. Vertex masses are the material's areal density times a third of the adjacent triangles'
area (the total is the cloth's mass; pinned vertices' mass is dropped).

Exported (:func:`export_scene`, :func:`scene_mjcf`) in that expanded form, not as a
``<flexcomp>``: flexcomp gives every point the same mass and pins points only to its parent body
(:data:`NOT_FLEXCOMP`; the strip hangs between the world and the clamp). The file writes one body
``cloth_<v>`` per free vertex ``v`` on one line, every number exact, and compiles to the model
:func:`build_scene` compiles.

Elasticity, default (the split of :mod:`yarnfit.mujoco.split`): MuJoCo's built-in isotropic
``<elasticity elastic2d="both">`` carries ``S_iso ⪰ S/2`` and a bending at least the material's,
integrated implicitly under the ``discrete`` integrator, which keeps the step stable; the
``yarnfit.shell`` plugin, configured with the full material, its weft angle and
``membrane="node"`` (:data:`DEFAULT_MEMBRANE`), removes MuJoCo's forces exactly and carries the
whole material, its membrane on node-smoothed strains (no locking on any triangulation). With
``membrane="triangle"`` it keeps constant-strain triangles and, with ``builtin_*`` keys repeating
the ``<elasticity>``, adds only the orthotropic membrane remainder (and all the bending; plugins/
README.md). With ``implicit_share="anisotropic"`` the plugin also writes MuJoCo's implicit
membrane as half the material's own tangent in each mode (its key ``implicit_share``, removed
exactly like the node membrane's share). With ``fallback=True`` the scene has no plugin: MuJoCo's
``elastic2d="both"`` with :func:`~yarnfit.mujoco.split.isotropic_fallback`. One damping time
(s) goes to both parts, so the total damping is that time times the full material's stiffness.

Scenes (:data:`SCENES`), z up, weft along world x unless ``angle`` turns it:

* ``cloth``: a horizontal square hanging from its two corners at ``x = −size/2``; it swings
  down under gravity. No contacts.
* ``stretch``: a FAB-style strip, ``size`` long along x and ``width`` wide, clamped on its short
  sides; the ``x = 0`` clamp is the world, the ``x = size`` clamp a body on a slide joint
  ``pull`` driven by the position actuator ``pull`` (control = clamp displacement in m, range
  0 to ``max_strain × size``). Sensors ``pull_force`` (actuator force, N) and ``pull_extension``
  (m). No gravity, no contacts: an in-plane test.
* ``sphere``: a horizontal square dropped onto a sphere of radius ``0.3 size`` on the floor.
* ``wall``: a horizontal square dropped centred across the top edge of a thin wall (a box
  ``0.02 × 1.2 size × 0.6 size``, thicker if the grid spacing exceeds 1.3 cm) on the floor.
"""

from __future__ import annotations

import math
import os
import re
import textwrap
import warnings
from dataclasses import dataclass

import mujoco
import numpy as np

from ..checks import non_negative_number, positive_number
from ..material_file import MaterialFile
from ..outputs import write_atomically
from ..shell import ShellMaterial
from . import (DEFAULT_DAMPING, DEFAULT_FRICTION, DEFAULT_IMPLICIT_DRAG, DEFAULT_IMPLICIT_SHARE, DEFAULT_INTEGRATOR,
               DEFAULT_MEMBRANE, DEFAULT_MESH, DEFAULT_RESOLUTION, DEFAULT_SIZE, DEFAULT_SOLVER, DEFAULT_TIMESTEP,
               EXPORT_RESOLUTION, EXPORT_SPLIT, IMPLICIT_DRAGS, IMPLICIT_SHARES, INTEGRATORS, MEMBRANES, MESHES,
               SCENES, SOLVERS)
from .plugin import PLUGIN_NAME
from .split import DEFAULT_STIFFENING_BOUND, MJCF_DIGITS, anisotropic_share, builtin_elasticity, isotropic_fallback

__all__ = [
    "DEFAULT_DAMPING",
    "DEFAULT_FRICTION",
    "DEFAULT_IMPLICIT_DRAG",
    "DEFAULT_INTEGRATOR",
    "DEFAULT_RESOLUTION",
    "DEFAULT_SIZE",
    "DEFAULT_SOLVER",
    "DEFAULT_TIMESTEP",
    "EXPORT_RESOLUTION",
    "EXPORT_SPLIT",
    "IMPLICIT_DRAGS",
    "INTEGRATORS",
    "SCENES",
    "SOLVERS",
    "BuiltScene",
    "ClothMaterial",
    "add_cloth_flex",
    "build_scene",
    "export_options",
    "export_scene",
    "scene_mjcf",
]

DEFAULT_STRIP_WIDTH = 0.05  # m
DEFAULT_MAX_STRAIN = 0.1  # the pull actuator's range: 10 % engineering strain
# MJCF integrator names (``yarnfit.mujoco.INTEGRATORS``) to MuJoCo's enum.
INTEGRATOR_ENUM = {"discrete": mujoco.mjtIntegrator.mjINT_DISCRETE, "euler": mujoco.mjtIntegrator.mjINT_EULER,
                   "rk4": mujoco.mjtIntegrator.mjINT_RK4}
# MJCF solver names (``yarnfit.mujoco.SOLVERS``) to MuJoCo's enum, and each enum's name as a
# summary prints it.
SOLVER_ENUM = {"newton": mujoco.mjtSolver.mjSOL_NEWTON, "cg": mujoco.mjtSolver.mjSOL_CG}
SOLVER_LABEL = {mujoco.mjtSolver.mjSOL_NEWTON: "Newton", mujoco.mjtSolver.mjSOL_CG: "CG"}


def solver_enum(solver: str) -> mujoco.mjtSolver:
    """MuJoCo's enum of the constraint solver named ``solver`` (one of :data:`SOLVERS`,
    case-insensitive); ``ValueError`` naming the choices otherwise."""
    key = str(solver).lower()
    if key not in SOLVER_ENUM:
        raise ValueError(f"unknown solver {solver!r}; solvers: {', '.join(SOLVERS)}")
    return SOLVER_ENUM[key]
# Collision radius of the flex (m): a few cloth thicknesses, small against the grid spacing
# (12.8 mm at the defaults) so the cloth does not float visibly above what it lies on.
FLEX_RADIUS = 2e-3
# Half the wall's thickness (m), unless the grid is coarser (see the wall scene).
WALL_HALF_THICKNESS = 0.01
# Gap between the dropped cloth and the obstacle's top at the start (m).
DROP_GAP = 0.02
# Stretch clamp: its mass (kg), and the servo stiffness over the strip's own (the clamp then lags
# its target by about 1 % of the extension under load).
CLAMP_MASS = 0.1
SERVO_STIFFNESS_RATIO = 100.0
# MJCF elastic2d names to mjtElastic2D values (none, bend, stretch, both).
ELASTIC2D = {"none": 0, "bend": 1, "stretch": 2, "both": 3}
# Exported scenes (export_scene): the default class of the cloth's vertex bodies, and why the cloth
# is written expanded rather than as a <flexcomp> (measured on MuJoCo 4.0.0; design notes §7).
VERTEX_CLASS = "cloth_vertex"
NOT_FLEXCOMP = ("flexcomp gives every point the same mass (its mass over the number of points, pinned points "
                "included), while this cloth's vertices carry the areal density times a third of their "
                "triangles' area, so that an edge vertex has half the mass of an interior one. No MJCF element "
                "can change the mass of a body a flexcomp made.")
SCENE_SUMMARY = {"cloth": "(a square hanging from two corners)",
                 "stretch": "(a strip between the world and the clamp on slide joint pull, actuator pull)",
                 "sphere": "(a square dropped onto a sphere)",
                 "wall": "(a square dropped across the top edge of a wall)"}

# MuJoCo 4.0.0 warns "flex ... is not rigid and has no equality constraints or passive forces" for a
# flex whose only elasticity is elastic2d="stretch", although it has passive forces (measured: the
# same flex with elastic2d="both" does not warn). Silenced where we compile our own scenes.
_SPURIOUS_FLEX_WARNING = r"flex '.*' is not rigid and has no equality constraints or passive forces"


@dataclass(frozen=True)
class ClothMaterial:
    """What a scene needs from a material file.

    Attributes:
        name: the fabric's name (``inputs.fabric``) or the file's stem.
        shell: the fitted shell.
        areal_density_kg_m2: mass per area (kg/m²).
    """

    name: str
    shell: ShellMaterial
    areal_density_kg_m2: float

    def __post_init__(self):
        density = self.areal_density_kg_m2
        if isinstance(density, bool) or not isinstance(density, (int, float)) or not (math.isfinite(density)
                                                                                     and density > 0):
            raise ValueError(f"areal density must be a positive number of kg/m², got {density!r}")

    @classmethod
    def from_file(cls, path: str | os.PathLike | MaterialFile,
                  areal_density_kg_m2: float | None = None, linear: bool = False) -> ClothMaterial:
        """Read a material file (``yarnfit fit`` output; at least ``shell`` and an areal density;
        a :class:`~yarnfit.material_file.MaterialFile` already read is taken as it is).

        The shell is the file's (with its strain-stiffening membrane and signed bending if it has
        them), or with ``linear`` the linear StVK fit from the same samples. The areal density is
        ``areal_density_kg_m2`` if given, else the file's ``inputs.areal_density_kg_m2``, else its
        ``yarn.areal_density_kg_m2`` (the relaxed repeat's).

        Raises:
            ValueError: ``<file>: ...`` for an unreadable or malformed file, a missing ``shell``,
                or no usable areal density.
        """
        file = MaterialFile.read(path)
        shell = file.linear_shell if linear else file.shell
        try:
            shell.check_positive_definite()
        except ValueError as exc:
            raise ValueError(f"{file.where}: shell: {exc}") from None
        if areal_density_kg_m2 is not None:
            return cls(file.name, shell, areal_density_kg_m2)
        found = file.areal_density()
        if found is None:
            raise ValueError(f"{file.where}: no areal density (inputs.areal_density_kg_m2 or "
                             "yarn.areal_density_kg_m2); give one")
        density, key = found
        try:
            return cls(file.name, shell, density)
        except ValueError as exc:
            raise ValueError(f"{file.where}: {key}: {exc}") from None


@dataclass(frozen=True)
class BuiltScene:
    """A scene and what went into its elasticity.

    Attributes:
        spec: the scene (``spec.compile()`` or ``spec.to_xml()``).
        scene: its name, one of :data:`SCENES`.
        fallback: True for the plugin-free isotropic scene.
        young_pa, poisson, thickness_m: the flex's ``<elasticity>`` (the built-in part of the
            split, or the fallback material).
        notes: what the fallback cannot carry over (empty with the plugin).
    """

    spec: mujoco.MjSpec
    scene: str
    fallback: bool
    young_pa: float
    poisson: float
    thickness_m: float
    notes: tuple[str, ...]


def build_scene(
    material: ClothMaterial,
    scene: str,
    *,
    resolution: int | None = None,
    size: float | None = None,
    timestep: float = DEFAULT_TIMESTEP,
    integrator: str = DEFAULT_INTEGRATOR,
    solver: str | None = None,
    friction: float = DEFAULT_FRICTION,
    damping: float = DEFAULT_DAMPING,
    angle: float = 0.0,
    fallback: bool = False,
    self_collision: bool = False,
    width: float = DEFAULT_STRIP_WIDTH,
    max_strain: float = DEFAULT_MAX_STRAIN,
    mesh: str = DEFAULT_MESH,
    implicit_bending: bool = True,
    stiffening_bound: float = DEFAULT_STIFFENING_BOUND,
    membrane: str = DEFAULT_MEMBRANE,
    implicit_drag: str = DEFAULT_IMPLICIT_DRAG,
    implicit_share: str = DEFAULT_IMPLICIT_SHARE,
) -> BuiltScene:
    """Build one of :data:`SCENES` for ``material`` (see the module docstring).

    Args:
        resolution: vertices per side (stretch: along the strip), ≥ 2; default
            :data:`DEFAULT_RESOLUTION`.
        size: side length (m) (stretch: strip length); default :data:`DEFAULT_SIZE`.
        timestep: Δt (s).
        integrator: one of :data:`INTEGRATORS` (case-insensitive).
        solver: MuJoCo's constraint solver, one of :data:`SOLVERS` (case-insensitive); default
            the scene's :data:`DEFAULT_SOLVER` (CG where the cloth touches something, Newton for
            the strip).
        friction: sliding friction of cloth and obstacles.
        damping: stiffness-proportional damping time (s) of the built-in part and the plugin.
        angle: weft direction (rad) from world x, about z (the plugin's ``angle``).
        fallback: no plugin; MuJoCo's isotropic ``elastic2d="both"`` with the fallback material.
        self_collision: let the cloth collide with itself (MuJoCo's ``selfcollide="auto"``).
        width: the strip's width (m), stretch only.
        max_strain: upper end of the pull actuator's range as engineering strain, stretch only.
        mesh: one of :data:`MESHES`: ``grid`` (one diagonal per cell) or ``crisscross`` (both
            diagonals and a centre vertex; no locking, twice the vertices): :func:`grid_mesh`.
        implicit_bending: the built-in part also bends (``elastic2d="both"``, integrated
            implicitly; the plugin removes it and bends with the material); ``False``: the plugin
            carries all the bending explicitly (``elastic2d="stretch"``, as before issue 15).
        stiffening_bound: the built-in membrane share also covers half the strain-stiffening
            membrane's tangent up to this strain (:func:`~yarnfit.mujoco.split.builtin_elasticity`).
        membrane: the plugin's membrane strains, one of :data:`MEMBRANES`: ``"node"`` (smoothed over
            each vertex's third of its triangles: no locking on any triangulation) or ``"triangle"``
            (constant per triangle: locks on one-diagonal and unstructured cells); plugins/README.md.
        implicit_drag: the plugin's ``implicit_drag``, one of :data:`IMPLICIT_DRAGS`: ``"full"``
            (all of the discrete step's drag through the built-in share) or ``"critical"`` (kept only
            where the material's modes need it to be damped critically; the stretch scene's strips).
        implicit_share: the implicit part's membrane, one of :data:`IMPLICIT_SHARES`:
            ``"isotropic"`` (MuJoCo's ``<elasticity>`` as compiled) or ``"anisotropic"`` (the
            plugin's ``implicit_share``, half the material's tangent in each mode, written over
            MuJoCo's metric: the soft modes are not held back; plugins/README.md, Split).

    Raises:
        ValueError: an unknown scene, integrator, solver or mesh, a non-positive resolution, size,
            timestep, width or max_strain, a negative friction or damping.
    """
    if scene not in SCENES:
        raise ValueError(f"unknown scene {scene!r}; scenes: {', '.join(SCENES)}")
    if mesh not in MESHES:
        raise ValueError(f"unknown mesh {mesh!r}; meshes: {', '.join(MESHES)}")
    resolution = DEFAULT_RESOLUTION[scene] if resolution is None else resolution
    size = DEFAULT_SIZE[scene] if size is None else size
    if isinstance(resolution, bool) or not isinstance(resolution, (int, np.integer)) or resolution < 2:
        raise ValueError(f"resolution must be an integer of at least 2 vertices per side, got {resolution!r}")
    for name, value in (("size", size), ("timestep", timestep), ("width", width), ("max_strain", max_strain)):
        positive_number(value, name)
    for name, value in (("friction", friction), ("damping", damping), ("angle", abs(angle))):
        non_negative_number(value, name)
    key = integrator.lower()
    if key not in INTEGRATOR_ENUM:
        raise ValueError(f"unknown integrator {integrator!r}; integrators: {', '.join(INTEGRATORS)}")
    solver_code = solver_enum(DEFAULT_SOLVER[scene] if solver is None else solver)

    spec = mujoco.MjSpec()
    spec.modelname = f"yarnfit {scene}: {material.name}" + (" (isotropic fallback)" if fallback else "")
    spec.option.timestep = timestep
    spec.option.integrator = INTEGRATOR_ENUM[key]
    spec.option.solver = solver_code
    spec.worldbody.add_light(pos=[0, 0, 3 * size + 1], dir=[0, 0, -1], type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL)
    if scene == "stretch":
        layout = _strip(spec, material.shell, resolution, size, width, max_strain, mesh == "crisscross")
    else:
        layout = _square(spec, scene, resolution, size, friction, mesh == "crisscross")

    elasticity = _Elasticity.of(spec, material, fallback, implicit_bending, stiffening_bound, angle, damping,
                                membrane=membrane, implicit_drag=implicit_drag, implicit_share=implicit_share)
    flex = _cloth(spec, layout, material.areal_density_kg_m2, elasticity.plugin)
    elasticity.apply(flex, damping, friction)
    flex.contype = flex.conaffinity = 1 if layout.collide else 0
    flex.selfcollide = mujoco.mjtFlexSelf.mjFLEXSELF_AUTO if self_collision else mujoco.mjtFlexSelf.mjFLEXSELF_NONE
    return BuiltScene(spec, scene, fallback, elasticity.young_pa, elasticity.poisson, elasticity.thickness_m,
                      elasticity.notes)


def export_options(scene: str, **options) -> dict:
    """:func:`build_scene`'s options for ``scene`` as ``yarnfit export`` writes it: ``options``, with
    the scene's :data:`EXPORT_SPLIT` (mesh, membrane, implicit share and drag) and
    :data:`EXPORT_RESOLUTION` wherever they leave them out or give ``None``."""
    if scene not in SCENES:
        raise ValueError(f"unknown scene {scene!r}; scenes: {', '.join(SCENES)}")
    given = {key: value for key, value in options.items() if value is not None}
    return {"resolution": EXPORT_RESOLUTION[scene], **EXPORT_SPLIT[scene], **given}


def export_scene(material: ClothMaterial | str | os.PathLike, scene: str, output: str | os.PathLike,
                 **options) -> BuiltScene:
    """Build a scene (``options`` as for :func:`build_scene`), write it to ``output`` as MJCF
    (:func:`scene_mjcf`; directories created) and check that the text compiles (a scene that does not
    compile is never written). ``material`` is a :class:`ClothMaterial` or a material file. The file
    loads with ``mujoco.MjModel.from_xml_path`` once ``mujoco`` is imported (our entry point
    registers the plugin) and compiles to the model ``build_scene`` compiles, number for number."""
    if not isinstance(material, ClothMaterial):
        material = ClothMaterial.from_file(material)
    built = build_scene(material, scene, **options)
    text = scene_mjcf(built)
    compile_quietly(mujoco.MjSpec.from_string(text))
    write_atomically(output, text)
    return built


def scene_mjcf(built: BuiltScene) -> str:
    """The scene as MJCF text that compiles to the model ``built.spec`` compiles (every array of
    mjModel equal), with a header comment that names the plugin and how to get it.

    MuJoCo writes it (``MjSpec.to_xml`` with ``savecompiled="false"``: every number exact, where the
    default writes 6 significant digits), except the cloth's vertex bodies, one line each in class
    :data:`VERTEX_CLASS` (slide joints). Not a ``<flexcomp>``, which cannot hold this cloth
    (:data:`NOT_FLEXCOMP`): the file spells out what MuJoCo expands a flexcomp into, one body
    ``cloth_<v>`` per free vertex ``v``, as ``build_scene`` builds it.
    """
    spec = built.spec.copy()
    spec.compiler.savecompiled = False  # exact numbers
    spec.compiler.savecanonical = False  # the servo as <position kp dampratio>, as it was built
    spec.comment = _header(built)
    vertex_class = spec.add_default(VERTEX_CLASS, spec.default)
    vertex_class.joint.type = mujoco.mjtJoint.mjJNT_SLIDE
    with warnings.catch_warnings():  # to_xml compiles the spec
        warnings.filterwarnings("ignore", message=_SPURIOUS_FLEX_WARNING)
        text = spec.to_xml()
    flex = spec.flexes[0]
    # build_scene adds the vertex bodies last: they are the world's last children in the text.
    vertices = [spec.body(name) for v, name in enumerate(flex.vertbody) if name == f"{flex.name}_{v}"]
    start = text.rindex("\n", 0, text.index(f'<body name="{vertices[0].name}"')) + 1
    end = text.rindex("  </worldbody>")
    if text.count("<body ", start, end) != len(vertices):
        raise RuntimeError(f"the {flex.name} flex's vertex bodies are not the last bodies of the world")
    block = [f"    <!-- The {flex.name} flex's free vertices: body {flex.name}_<v> holds vertex v with a third of the",
             f"         mass of each of its triangles; class {VERTEX_CLASS} makes its joints slides. Pinned vertices",
             "         sit on their holder (the flex's body list). -->",
             f'    <frame childclass="{VERTEX_CLASS}">',
             *(f"      {_vertex_body(body)}" for body in vertices),
             "    </frame>\n"]
    return text[:start] + "\n".join(block) + text[end:]


def _vertex_body(body: mujoco.MjsBody) -> str:
    """One vertex body of :func:`_cloth` as one line of MJCF, its joints in class :data:`VERTEX_CLASS`."""
    if np.any(body.ipos) or not np.array_equal(body.iquat, [1, 0, 0, 0]) or body.quat[0] != 1:
        raise RuntimeError(f"vertex body {body.name} is not a point mass at its origin")
    joints = []
    for joint in body.joints:
        if joint.type != mujoco.mjtJoint.mjJNT_SLIDE or joint.name or np.any(joint.pos):
            raise RuntimeError(f"vertex body {body.name} has a joint other than an unnamed slide")
        joints.append(f'<joint axis="{_reals(joint.axis)}"/>')
    plugin = f'<plugin instance="{body.plugin.name}"/>' if body.plugin.active else ""
    return (f'<body name="{body.name}" pos="{_reals(body.pos)}"><inertial pos="0 0 0" mass="{_real(body.mass)}" '
            f'diaginertia="{_reals(body.inertia)}"/>{"".join(joints)}{plugin}</body>')


def _real(value: float) -> str:
    """``value`` exactly (the shortest text that reads back to the same double), as MuJoCo writes it."""
    text = repr(float(value))
    return text[:-2] if text.endswith(".0") else text


def _reals(values) -> str:
    return " ".join(_real(value) for value in values)


def _header(built: BuiltScene) -> str:
    """The comment at the top of an exported scene: what it is, the plugin and how to get it, why
    the cloth is not a ``<flexcomp>``. MuJoCo keeps the first comment in ``<mujoco>`` as
    ``MjSpec.comment`` and writes it back when it saves the model. XML comments cannot hold two
    hyphens in a row (expat refuses the file; MuJoCo does not mind), so the fallback option is named
    in words."""
    spec, flex = built.spec, built.spec.flexes[0]
    holders = list(dict.fromkeys(name for v, name in enumerate(flex.vertbody) if name != f"{flex.name}_{v}"))
    paragraphs = [f"{spec.modelname}: the {built.scene} scene {SCENE_SUMMARY[built.scene]}, written by yarnfit "
                  "export (yarnfit.mujoco.scenes.export_scene). Lengths in m, masses in kg, times in s."]
    if built.fallback:
        paragraphs += [f'Isotropic fallback, no plugin: the flex "{flex.name}" carries MuJoCo\'s own elasticity '
                       'alone (elastic2d="both"), one isotropic material with the fitted one\'s geometric-mean '
                       "stretch and bending stiffness. It loads in plain MuJoCo 4.0. "
                       + (f"What it cannot carry over: {'; '.join(built.notes)}. " if built.notes else "")
                       + f"The fitted orthotropic material needs the engine plugin {PLUGIN_NAME} (pip install "
                       "yarnfit); yarnfit export without its fallback option writes this scene with it."]
    else:
        config = spec.plugins[0].config
        membrane = config.get("membrane", "triangle")
        paragraphs += [f'The cloth is the 2D flex "{flex.name}", driven by the MuJoCo engine plugin {PLUGIN_NAME} '
                       f'(instance "{spec.plugins[0].name}", configured in <extension>): the fitted orthotropic '
                       "shell, membrane s00 s01 s11 s22 and bending b00 b01 b11 b22 (Pa), thickness (m)"
                       + (" (with ridges: the strain-stiffening membrane's base, and its ridges n0 n1 n2 "
                          "knot stiffness)" if "ridges" in config else "")
                       + ", the weft angle (rad from world x), a damping time (s) and membrane strains "
                       + ('smoothed over each vertex (membrane="node")' if membrane == "node"
                          else f'constant per triangle (membrane="{membrane}")')
                       + ". The flex's own <elasticity> is MuJoCo's implicit isotropic share that keeps the step "
                       + ("stable; the plugin adds the rest of the material to it (builtin_young, builtin_poisson "
                          "and builtin_thickness repeat it)." if "builtin_young" in config else
                          "stable; the plugin removes its forces and carries the whole material.")
                       + (" Under the discrete integrator that share also drags the cloth (the step's -h K v); "
                          'with implicit_drag="critical" the plugin gives back what the material\'s soft modes '
                          "(a woven's shear) do not need to be damped critically, so they come to rest sooner."
                          if config.get("implicit_drag") == "critical" else ""),
                       "Getting the plugin: pip install yarnfit. Then import mujoco registers it in Python "
                       "(yarnfit's mujoco.plugins entry point) and mujoco.MjModel.from_xml_path loads this file "
                       "as it is; a C or C++ host first calls mj_loadPluginLibrary on "
                       "yarnfit/mujoco/libyarnfit_shell.so in the installed package (python -c \"from "
                       'yarnfit.mujoco.plugin import LIBRARY; print(LIBRARY)" prints its path). Without it MuJoCo '
                       "stops with "
                       f'"plugin {PLUGIN_NAME} not found": yarnfit export with its fallback option writes the '
                       "scene without the plugin (MuJoCo's isotropic elasticity alone)."]
    paragraphs += ["Not a <flexcomp>: " + NOT_FLEXCOMP
                   + (f" Nor can a flexcomp pin this cloth: it pins points only to the body it is in, and this "
                      f"cloth is held by the {' and the '.join(holders)}." if len(holders) > 1 else "")
                   + f" So the cloth is written as MuJoCo expands a flexcomp: one body {flex.name}_<v> per free "
                   f"vertex v (three world-axis slide joints{'' if built.fallback else ', the plugin'}), pinned "
                   f'vertices on their holder, and <flex name="{flex.name}">. Every number is exact: this file '
                   "compiles to the model yarnfit simulates (build_scene)."]
    text = "\n\n".join(textwrap.fill(paragraph, width=98, initial_indent="  ", subsequent_indent="  ",
                                     break_long_words=False, break_on_hyphens=False) for paragraph in paragraphs)
    return "\n" + re.sub("-(?=-)", "- ", text) + "\n"  # a fabric's name may hold "--"


def compile_quietly(spec: mujoco.MjSpec) -> mujoco.MjModel:
    """``spec.compile()`` without MuJoCo's spurious warning for stretch-only flexes."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=_SPURIOUS_FLEX_WARNING)
        return spec.compile()


# -- pieces ---------------------------------------------------------------------------------------


@dataclass
class _Layout:
    """Rest positions ``(n, 3)`` (m), triangles ``(m, 3)``, the vertices pinned to each holder body
    (name → mask ``(n,)``) and whether the cloth collides at all."""

    points: np.ndarray
    triangles: np.ndarray
    holders: dict[str, np.ndarray]
    collide: bool


def _square(spec: mujoco.MjSpec, scene: str, resolution: int, size: float, friction: float,
            crisscross: bool) -> _Layout:
    """The cloth, sphere and wall scenes: a horizontal square and what it hangs from or falls on."""
    points, triangles = grid_mesh(resolution, resolution, size, size, crisscross)
    geom_friction = [friction, 0.005, 0.0001]
    if scene == "cloth":
        points[:, 2] = size + 0.1
        corners = np.zeros(len(points), bool)
        corners[[0, resolution - 1]] = True  # (x, y) = (−size/2, ∓size/2)
        return _Layout(points, triangles, {"world": corners}, collide=False)
    spec.worldbody.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[2 * size, 2 * size, 0.1],
                            friction=geom_friction, rgba=[0.8, 0.8, 0.8, 1])
    if scene == "sphere":
        radius = 0.3 * size
        spec.worldbody.add_geom(name="sphere", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[radius, 0, 0],
                                pos=[0, 0, radius], friction=geom_friction, rgba=[0.6, 0.6, 0.65, 1])
        points[:, 2] = 2 * radius + DROP_GAP
    else:  # wall
        height = 0.6 * size
        # MuJoCo collides a flex with geoms through spheres of its radius at the vertices (measured:
        # every contact lies within the radius of a vertex), so a wall thinner than the grid spacing
        # can slip between two vertex columns: a 20-vertex cloth fell through a 2 cm wall. At 1.5
        # spacings at least one column always lands on top.
        half_thickness = max(WALL_HALF_THICKNESS, 0.75 * size / (resolution - 1))
        spec.worldbody.add_geom(name="wall", type=mujoco.mjtGeom.mjGEOM_BOX, size=[half_thickness, 0.6 * size,
                                0.5 * height], pos=[0, 0, 0.5 * height], friction=geom_friction,
                                rgba=[0.6, 0.6, 0.65, 1])
        points[:, 2] = height + DROP_GAP
    return _Layout(points, triangles, {}, collide=True)


def _strip(spec: mujoco.MjSpec, shell: ShellMaterial, resolution: int, length: float, width: float,
           max_strain: float, crisscross: bool) -> _Layout:
    """The stretch scene: a strip from x = 0 to ``length``, its left edge on the world, its right
    edge on the clamp; no gravity."""
    spec.option.gravity = [0.0, 0.0, 0.0]
    ny = strip_columns(resolution, length, width)
    points, triangles = grid_mesh(resolution, ny, length, width, crisscross)
    points[:, 0] += 0.5 * length
    points[:, 2] = 0.1
    column = np.arange(len(points)) // ny  # grid vertices first; cell centres never on a clamp
    left, right = column == 0, column == resolution - 1
    clamp = _clamp(spec, shell, length, width, max_strain, position=[length, 0.0, 0.1])
    return _Layout(points, triangles, {"world": left, clamp.name: right}, collide=False)


def strip_columns(resolution: int, length: float, width: float) -> int:
    """Vertices across a strip with ``resolution`` vertices along its ``length``: the same spacing
    across its ``width`` (m), at least 2."""
    return max(2, round((resolution - 1) * width / length) + 1)


def grid_mesh(nx: int, ny: int, lx: float, ly: float, crisscross: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Vertices of an ``lx × ly`` grid centred at the origin (vertex ``ix ny + iy``; ``(nx ny, 3)``)
    and its triangles, counter-clockwise seen from +z (flexcomp's order).

    ``crisscross=False``: each cell split by one diagonal, ``2 (nx−1)(ny−1)`` triangles.
    ``crisscross=True``: each cell split by both diagonals around a centre vertex (the centres
    follow the grid vertices, cell ``(ix, iy)`` at ``nx ny + ix (ny−1) + iy``), ``4 (nx−1)(ny−1)``
    triangles. Constant-strain triangles with one diagonal lock when the material resists a
    deformation the mesh cannot follow without stretching stiff directions: a shear-soft woven
    cut on the bias (its fibres along the diagonals) or a knit whose area is nearly conserved
    (design notes §7); criss-cross cells have edges along both diagonals and do not.
    """
    x, y = np.meshgrid(np.linspace(-0.5 * lx, 0.5 * lx, nx), np.linspace(-0.5 * ly, 0.5 * ly, ny), indexing="ij")
    points = np.column_stack([x.ravel(), y.ravel(), np.zeros(nx * ny)])
    a = (np.arange(nx - 1)[:, None] * ny + np.arange(ny - 1)[None, :]).ravel()
    if not crisscross:
        triangles = np.concatenate([np.stack([a, a + ny, a + ny + 1], 1), np.stack([a, a + ny + 1, a + 1], 1)])
        return points, triangles
    centres = np.column_stack([0.5 * (x[:-1, :-1] + x[1:, 1:]).ravel(), 0.5 * (y[:-1, :-1] + y[1:, 1:]).ravel(),
                               np.zeros((nx - 1) * (ny - 1))])
    m = nx * ny + np.arange((nx - 1) * (ny - 1))
    b, c, d = a + ny, a + ny + 1, a + 1
    triangles = np.concatenate([np.stack([a, b, m], 1), np.stack([b, c, m], 1), np.stack([c, d, m], 1),
                                np.stack([d, a, m], 1)])
    return np.vstack([points, centres]), triangles


# Unstructured panel meshes (panel_mesh): interior points on a hexagonal lattice moved by up to this
# fraction of the cell (seeded, so a mesh is reproducible), and kept at least this fraction of a
# cell from the outline, where the outline's own points are.
PANEL_JITTER = 0.15
PANEL_MARGIN = 0.5


def panel_mesh(outline: np.ndarray, cell: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """An unstructured triangulation of the flat panel inside the closed polygon ``outline (k, 2)``
    (m, counter-clockwise or not; convex or not), about ``cell`` (m) between vertices: points every
    ``≤ cell`` along the outline and on a jittered hexagonal lattice inside (:data:`PANEL_JITTER`,
    seeded by ``seed``), Delaunay-triangulated, triangles whose centroid lies outside dropped.
    Returns vertices ``(n, 3)`` (z = 0) and triangles ``(m, 3)``, counter-clockwise seen from +z.
    Edges run in every direction: a mesh with no preferred lines, like a garment panel's.

    Raises:
        ValueError: fewer than 3 outline points, a non-positive cell.
    """
    from scipy.spatial import Delaunay

    outline = np.asarray(outline, dtype=float)
    if outline.ndim != 2 or outline.shape[1] != 2 or len(outline) < 3:
        raise ValueError(f"outline must be (k >= 3, 2) points, got shape {outline.shape}")
    positive_number(cell, "cell")
    boundary = []
    for a, b in zip(outline, np.roll(outline, -1, axis=0)):
        count = max(1, math.ceil(np.linalg.norm(b - a) / cell))
        boundary.append(a + (b - a) * (np.arange(count)[:, None] / count))
    boundary = np.vstack(boundary)
    low, high = outline.min(0), outline.max(0)
    rows = np.arange(low[1], high[1] + cell, cell * math.sqrt(3) / 2)
    lattice = []
    for k, y in enumerate(rows):  # every other row shifted by half a cell
        x = np.arange(low[0] + (0.5 * cell if k % 2 else 0.0), high[0] + cell, cell)
        lattice.append(np.column_stack([x, np.full(len(x), y)]))
    lattice = np.vstack(lattice)
    lattice += np.random.default_rng(seed).uniform(-PANEL_JITTER, PANEL_JITTER, lattice.shape) * cell
    keep = _inside(lattice, outline) & (_distance_to_outline(lattice, outline) > PANEL_MARGIN * cell)
    xy = np.vstack([boundary, lattice[keep]])
    triangles = Delaunay(xy).simplices.astype(int)
    triangles = triangles[_inside(xy[triangles].mean(axis=1), outline)]
    triangles = _counter_clockwise(xy, triangles)
    used = np.unique(triangles)
    index = np.full(len(xy), -1)
    index[used] = np.arange(len(used))
    return np.column_stack([xy[used], np.zeros(len(used))]), index[triangles]


def _inside(points: np.ndarray, outline: np.ndarray) -> np.ndarray:
    """``(n,)`` whether each point ``(n, 2)`` lies inside the polygon ``outline (k, 2)`` (even-odd)."""
    x, y = points[:, 0:1], points[:, 1:2]
    a, b = outline, np.roll(outline, -1, axis=0)
    crosses = (a[:, 1] > y) != (b[:, 1] > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        at = a[:, 0] + (y - a[:, 1]) * (b[:, 0] - a[:, 0]) / (b[:, 1] - a[:, 1])
    return (np.count_nonzero(crosses & (x < at), axis=1) % 2) == 1


def _distance_to_outline(points: np.ndarray, outline: np.ndarray) -> np.ndarray:
    """``(n,)`` distance (m) of each point ``(n, 2)`` to the polygon's edges."""
    a, b = outline[None], np.roll(outline, -1, axis=0)[None]
    p = points[:, None]
    edge = b - a
    t = np.clip(((p - a) * edge).sum(-1) / (edge**2).sum(-1), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[..., None] * edge), axis=-1).min(axis=1)


def _counter_clockwise(xy: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """``triangles (m, 3)`` over the points ``xy (n, 2)``, each reordered to run counter-clockwise
    seen from +z (a copy)."""
    triangles = np.array(triangles)
    a, b, c = (xy[triangles[:, i]] for i in range(3))
    clockwise = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1]) < 0
    triangles[clockwise] = triangles[clockwise][:, [0, 2, 1]]
    return triangles


def disc_mesh(radius: float, cell: float, rings_at=()) -> tuple[np.ndarray, np.ndarray]:
    """An unstructured triangulation of a disc of ``radius`` (m) centred at the origin in the plane
    z = 0: vertices ``(n, 3)`` (m) and triangles ``(m, 3)``, counter-clockwise seen from +z.

    A centre vertex and concentric rings of vertices, a ring exactly at each radius of
    ``rings_at`` (m, inside the disc: e.g. a clamp's edge) and at ``radius``; between those, rings
    about ``cell`` (m) apart, each with about ``cell`` between its vertices, every other ring turned
    by half its spacing; triangulated by Delaunay (the outer ring is a convex polygon, so every
    triangle lies in the disc). Triangle angles lie between about 39° and 91° at any cell size
    (measured from 2.5 cm to 5 mm cells on a 15 cm disc); the polygon's area falls short of
    π radius² by ``(2π/n)²/6`` of it, n the outer ring's vertices (0.17 % at 1.5 cm cells on
    15 cm, 0.46 % at 2.5 cm).

    Raises:
        ValueError: a non-positive radius or cell, a ring radius outside (0, radius).
    """
    from scipy.spatial import Delaunay

    positive_number(radius, "radius")
    positive_number(cell, "cell")
    rings = sorted({float(r) for r in rings_at})
    if any(not 0 < r < radius for r in rings):
        raise ValueError(f"rings_at must lie strictly inside the disc (0, {radius!r}), got {tuple(rings_at)!r}")
    bounds = [0.0, *rings, float(radius)]
    radii = []
    for inner, outer in zip(bounds[:-1], bounds[1:]):
        count = max(1, round((outer - inner) / cell))
        radii += [inner + (outer - inner) * (j + 1) / count for j in range(count)]
    xy = [np.zeros((1, 2))]
    for k, r in enumerate(radii):
        n = max(6, round(2 * math.pi * r / cell))
        turn = 2 * math.pi * (np.arange(n) + 0.5 * (k % 2)) / n
        xy.append(np.column_stack([r * np.cos(turn), r * np.sin(turn)]))
    xy = np.vstack(xy)
    triangles = Delaunay(xy).simplices.astype(int)
    triangles = _counter_clockwise(xy, triangles)
    return np.column_stack([xy, np.zeros(len(xy))]), triangles


def _lumped_mass(points: np.ndarray, triangles: np.ndarray, areal_density: float) -> np.ndarray:
    """Mass per vertex (kg): a third of each adjacent triangle's mass."""
    e1 = points[triangles[:, 1]] - points[triangles[:, 0]]
    e2 = points[triangles[:, 2]] - points[triangles[:, 0]]
    area = 0.5 * np.linalg.norm(np.cross(e1, e2), axis=1)
    mass = np.zeros(len(points))
    np.add.at(mass, triangles.ravel(), np.repeat(areal_density * area / 3.0, 3))
    return mass


def _cloth(spec: mujoco.MjSpec, layout: _Layout, areal_density: float, plugin, name: str = "cloth") -> mujoco.MjsFlex:
    """Vertex bodies ``<name>_<v>`` (three world-axis slide joints each) and the flex ``name``. Pinned
    vertices sit on their holder at their rest position; every body holding a vertex carries the
    plugin, as flexcomp does."""
    points = layout.points
    mass = _lumped_mass(points, layout.triangles, areal_density)
    body_of = ["" for _ in points]
    offsets = np.zeros_like(points)
    for holder_name, mask in layout.holders.items():
        holder = spec.worldbody if holder_name == "world" else spec.body(holder_name)
        origin = np.zeros(3) if holder_name == "world" else np.asarray(holder.pos)
        for v in np.flatnonzero(mask):
            body_of[v], offsets[v] = holder_name, points[v] - origin
        if plugin is not None:
            holder.plugin = plugin
    for v, point in enumerate(points):
        if body_of[v]:
            continue
        body = spec.worldbody.add_body(name=f"{name}_{v}", pos=point)
        # Slide joints only: the inertia never enters, but MuJoCo wants it positive. A sphere of the
        # collision radius.
        body.explicitinertial = True
        body.mass, body.ipos, body.iquat = mass[v], [0, 0, 0], [1, 0, 0, 0]
        body.inertia = [0.4 * mass[v] * FLEX_RADIUS**2] * 3
        for axis in np.eye(3):
            body.add_joint(type=mujoco.mjtJoint.mjJNT_SLIDE, axis=axis)
        if plugin is not None:
            body.plugin = plugin
        body_of[v] = body.name
    return spec.add_flex(name=name, dim=2, radius=FLEX_RADIUS, vertbody=body_of, vert=offsets.ravel(),
                         elem=layout.triangles.ravel(), rgba=[0.85, 0.45, 0.3, 1.0])


@dataclass(frozen=True)
class _Elasticity:
    """A cloth flex's elasticity: MuJoCo's built-in ``<elasticity>`` (E Pa, ν, t m, ``elastic2d``)
    and the ``yarnfit.shell`` instance beside it (None for the isotropic fallback), with the
    fallback's notes."""

    young_pa: float
    poisson: float
    thickness_m: float
    elastic2d: str
    plugin: object
    notes: tuple[str, ...]

    @classmethod
    def of(cls, spec, material: ClothMaterial, fallback: bool, implicit_bending: bool, stiffening_bound: float,
           angle: float, damping: float, name: str = "shell", rest: str = "qpos0",
           membrane: str = DEFAULT_MEMBRANE, implicit_drag: str = DEFAULT_IMPLICIT_DRAG,
           implicit_share: str = DEFAULT_IMPLICIT_SHARE) -> "_Elasticity":
        """The split of :func:`~yarnfit.mujoco.split.builtin_elasticity` with its plugin instance
        ``name`` added to ``spec``, or with ``fallback`` the isotropic fallback alone."""
        if membrane not in MEMBRANES:
            raise ValueError(f"unknown membrane {membrane!r}; membranes: {', '.join(MEMBRANES)}")
        if implicit_drag not in IMPLICIT_DRAGS:
            raise ValueError(f"unknown implicit_drag {implicit_drag!r}; choices: {', '.join(IMPLICIT_DRAGS)}")
        if implicit_share not in IMPLICIT_SHARES:
            raise ValueError(f"unknown implicit_share {implicit_share!r}; choices: {', '.join(IMPLICIT_SHARES)}")
        if fallback and implicit_share != "isotropic":
            raise ValueError(f"implicit_share {implicit_share!r} is written by the plugin, and the fallback has none")
        if fallback:
            iso = isotropic_fallback(material.shell)
            return cls(iso.young_pa, iso.poisson, iso.thickness_m, "both", None, iso.notes)
        split = builtin_elasticity(material.shell, bending=implicit_bending, stiffening_bound=stiffening_bound)
        plugin = _plugin(spec, material.shell, split, angle, damping, name=name, rest=rest, membrane=membrane,
                         implicit_drag=implicit_drag,
                         share=anisotropic_share(material.shell, stiffening_bound) if implicit_share == "anisotropic"
                         else None)
        return cls(split.young_pa, split.poisson, split.thickness_m, split.elastic2d, plugin, ())

    def apply(self, flex: mujoco.MjsFlex, damping: float, friction: float) -> None:
        """Write the built-in part, the damping time (s) and the sliding friction onto ``flex``."""
        flex.young, flex.poisson, flex.thickness, flex.damping = self.young_pa, self.poisson, self.thickness_m, damping
        flex.elastic2d = ELASTIC2D[self.elastic2d]
        flex.friction = [friction, 0.005, 0.0001]


def _plugin(spec: mujoco.MjSpec, shell: ShellMaterial, split, angle: float, damping: float, name: str = "shell",
            rest: str = "qpos0", membrane: str = DEFAULT_MEMBRANE, implicit_drag: str = DEFAULT_IMPLICIT_DRAG,
            share: np.ndarray | None = None):
    """The ``yarnfit.shell`` instance ``name``: the full material, its angle and damping, its rest
    (``"qpos0"`` or ``"texcoord"``), its membrane strains (``"triangle"`` or ``"node"``), its
    ``implicit_drag`` (written unless ``"full"``, the plugin's default), the anisotropic implicit
    share ``share (3, 3)`` (Pa) as ``implicit_share`` if given and, for the qpos0 rest with triangle
    strains and no such share, ``builtin_*`` written exactly as the ``<elasticity>`` attributes are
    (``MJCF_DIGITS`` digits)."""
    spec.activate_plugin(PLUGIN_NAME)
    plugin = spec.add_plugin(name=name, plugin_name=PLUGIN_NAME, active=True)
    config = {name: repr(value) for name, value in shell.parameters.items()}
    if shell.nonlinear is not None:  # the ridge membrane: its base as s00 ... s22, and its ridges (plugins/README.md)
        config.update(shell.nonlinear.plugin_keys)
    if shell.signed_bending is not None:  # b00 b11 the positive side's, b00_neg b11_neg the negative's
        config.update(shell.signed_bending.plugin_keys)
    config["thickness"] = repr(shell.thickness)
    config["angle"] = repr(float(angle))
    config["damping"] = repr(float(damping))
    if share is not None:  # upper triangle c00 c01 c02 c11 c12 c22, every digit (plugins/README.md, Split)
        config["implicit_share"] = " ".join(repr(float(share[i, j])) for i, j in ((0, 0), (0, 1), (0, 2), (1, 1),
                                                                                  (1, 2), (2, 2)))
    elif rest == "qpos0" and membrane == "triangle":
        for key, value in (("builtin_young", split.young_pa), ("builtin_poisson", split.poisson),
                           ("builtin_thickness", split.thickness_m)):
            config[key] = f"{value:.{MJCF_DIGITS}g}"
    # Otherwise the plugin removes MuJoCo's built-in part exactly and needs no keys for it.
    if rest != "qpos0":
        config["rest"] = rest
    if membrane != "triangle":
        config["membrane"] = membrane
    if implicit_drag != "full":
        config["implicit_drag"] = implicit_drag
    plugin.config = config
    return plugin


def _clamp(spec: mujoco.MjSpec, shell: ShellMaterial, length: float, width: float, max_strain: float,
           position: list[float]):
    """The moving clamp of the stretch scene: a body on slide joint ``pull`` (x), position actuator
    ``pull`` and sensors ``pull_force`` (N) and ``pull_extension`` (m)."""
    eng = shell.engineering()
    # The strip's axial stiffness (N/m) along its stiffer material direction, whichever way it is cut.
    strip = max(eng["weft_stretch_n_per_m"], eng["warp_stretch_n_per_m"]) * width / length
    clamp = spec.worldbody.add_body(name="clamp", pos=position)
    clamp.explicitinertial = True
    clamp.mass, clamp.ipos, clamp.iquat = CLAMP_MASS, [0, 0, 0], [1, 0, 0, 0]
    clamp.inertia = [CLAMP_MASS * width**2 / 12] * 3
    clamp.add_joint(name="pull", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[1, 0, 0])
    clamp.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.002, 0.5 * width + 0.002, 0.002], contype=0,
                   conaffinity=0, rgba=[0.3, 0.3, 0.35, 1], mass=0)
    actuator = spec.add_actuator(name="pull", target="pull", trntype=mujoco.mjtTrn.mjTRN_JOINT)
    actuator.set_to_position(kp=SERVO_STIFFNESS_RATIO * strip, dampratio=1.0)
    actuator.ctrllimited = True
    actuator.ctrlrange = [0.0, max_strain * length]
    spec.add_sensor(name="pull_force", type=mujoco.mjtSensor.mjSENS_ACTUATORFRC,
                    objtype=mujoco.mjtObj.mjOBJ_ACTUATOR, objname="pull")
    spec.add_sensor(name="pull_extension", type=mujoco.mjtSensor.mjSENS_JOINTPOS,
                    objtype=mujoco.mjtObj.mjOBJ_JOINT, objname="pull")
    return clamp


def add_cloth_flex(spec: mujoco.MjSpec, name: str, points: np.ndarray, triangles: np.ndarray,
                   material: ClothMaterial, *, damping: float = DEFAULT_DAMPING, friction: float = DEFAULT_FRICTION,
                   angle: float = 0.0, contype: int = 1, conaffinity: int = 1,
                   implicit_bending: bool = True, pinned: np.ndarray | None = None,
                   stiffening_bound: float = DEFAULT_STIFFENING_BOUND,
                   rest_uv: np.ndarray | None = None, fallback: bool = False,
                   membrane: str = DEFAULT_MEMBRANE, implicit_drag: str = DEFAULT_IMPLICIT_DRAG,
                   implicit_share: str = DEFAULT_IMPLICIT_SHARE) -> mujoco.MjsFlex:
    """One free 2D flex ``name`` with rest positions ``points (n, 3)`` (m) and ``triangles (m, 3)``,
    built as :func:`build_scene` builds its cloth (vertex bodies ``<name>_<v>`` with three slide
    joints, the split's built-in ``<elasticity>`` and a ``yarnfit.shell`` instance
    ``<name>_shell`` with the full material). The plugin's rest shape is the flex at ``qpos0`` in
    the frame of triangle 0's plane: give it a flat (planar) panel, or give ``rest_uv (m, 3, 2)``,
    each triangle corner's material coordinates in its pattern panel (m; a garment,
    :mod:`yarnfit.mujoco.garment`): they become the flex's texture coordinates, the plugin takes its
    rest from them (``rest="texcoord"``) and ``points`` are only where the cloth starts; call
    :func:`yarnfit.mujoco.garment.use_pattern_rest` on the compiled model. The vertices of the mask
    ``pinned (n,)``, if given, are held on the world at their rest positions (a clamp; the world
    then carries the plugin, as in the ``cloth`` scene). ``fallback``: no plugin, MuJoCo's own
    isotropic elasticity alone with :func:`~yarnfit.mujoco.split.isotropic_fallback`'s material
    (``elastic2d="both"``), as :func:`build_scene` builds it. ``membrane``, ``implicit_drag``,
    ``implicit_share``: as for :func:`build_scene`."""
    elasticity = _Elasticity.of(spec, material, fallback, implicit_bending, stiffening_bound, angle, damping,
                                name=f"{name}_shell", rest="qpos0" if rest_uv is None else "texcoord",
                                membrane=membrane, implicit_drag=implicit_drag, implicit_share=implicit_share)
    holders = {} if pinned is None else {"world": np.asarray(pinned, bool)}
    layout = _Layout(np.asarray(points, float), np.asarray(triangles, int), holders, collide=True)
    flex = _cloth(spec, layout, material.areal_density_kg_m2, elasticity.plugin, name=name)
    elasticity.apply(flex, damping, friction)
    flex.contype, flex.conaffinity = contype, conaffinity
    flex.selfcollide = mujoco.mjtFlexSelf.mjFLEXSELF_NONE
    if rest_uv is not None:
        rest_uv = np.asarray(rest_uv, float)
        if rest_uv.shape != (len(layout.triangles), 3, 2):
            raise ValueError(f"rest_uv must be (triangles, 3, 2) = ({len(layout.triangles)}, 3, 2), got {rest_uv.shape}")
        flex.texcoord = rest_uv.astype(np.float32).ravel()
        flex.elemtexcoord = np.arange(rest_uv.shape[0] * 3)
    return flex
