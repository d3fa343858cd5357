"""MuJoCo side of yarnfit: the ``yarnfit.shell`` engine plugin (loaded by ``plugin.load``, which
``import mujoco`` calls through the ``mujoco.plugins`` entry point), the split of a fitted
material between MuJoCo's built-in elasticity and the plugin (``split``), scenes built with
``mujoco.MjSpec`` (``scenes``) and a stability check that steps them (``run``).

This file imports nothing: ``import mujoco`` imports it through the entry point, and the command
line builds its parser from the scene names and defaults below without importing ``mujoco``.
"""

SCENES = ("cloth", "stretch", "sphere", "wall")
# MuJoCo's integrators a flex with elasticity runs under, by MJCF name, lower case. MuJoCo 4.0
# refuses the others at the first step: "flex elasticity is no longer integrated implicitly under
# integrator='implicit' and 'implicitfast': set integrator='discrete', or 'Euler' with a small
# timestep".
INTEGRATORS = ("discrete", "euler", "rk4")
# Measured (README, "Export to MuJoCo"): discrete keeps the built-in part implicit in position.
DEFAULT_INTEGRATOR = "discrete"
DEFAULT_TIMESTEP = 1e-3  # s
# The cloth's mesh (scenes.grid_mesh): one diagonal per cell ("grid"), or both diagonals around a
# centre vertex ("crisscross": no locking with triangle strains, twice the vertices).
MESHES = ("grid", "crisscross")
DEFAULT_MESH = "grid"
# The plugin's membrane strains: smoothed over each vertex's third of its triangles ("node", no
# locking on any triangulation; the default), or constant per triangle ("triangle", which locks on
# one-diagonal and unstructured cells); plugins/README.md.
MEMBRANES = ("node", "triangle")
DEFAULT_MEMBRANE = "node"
# MuJoCo's constraint solvers a scene may ask for, by MJCF name, lower case, and each scene's own.
# CG where the cloth touches something: Newton factorises the implicit flex metric's Hessian every
# iteration, CG does not. Measured (session 57, cotton twill, one run each, the export's defaults):
# the sphere scene 37.2 ms a step with Newton against 18.7 with CG, its centre of mass after 0.5 s
# 0.2323 against 0.2328 m; the hanging cloth (no contacts) 10.9 against 11.2 ms; the drapes'
# sphere 0.5945 against 0.5944 in drape coefficient (validate.drape, session 49). `bench.py mujoco`
# (the test woven, 40 x 40, both solvers in one run): sphere 79.6 ms with Newton, 20.1 with CG;
# hanging 11.1 against 12.3 (Newton ~10 % faster without contacts, CG kept there for a cloth that
# meets something: a wall, a gripper, itself). Newton for the FAB strip: there CG took 3.2 times as
# long (the twill's 8 x 5 weft strip pulled to 10 %: 34.3 against 10.7 s, the same forces to 3e-5
# N/m) and MuJoCo warned that the clamped strip's flex stiffness was too ill-conditioned for CG's
# effective-metric preconditioner.
SOLVERS = ("newton", "cg")
DEFAULT_SOLVER = {"cloth": "cg", "stretch": "newton", "sphere": "cg", "wall": "cg"}
# Vertices per side (stretch: along the strip). 40 resolves a 0.5 m cloth at 12.8 mm; the strip's
# 25 × 16 grid resolves the 8 × 5 cm FAB strip at 3.3 mm, where its uniform part is exact for
# linear triangles anyway.
DEFAULT_RESOLUTION = {"cloth": 40, "stretch": 25, "sphere": 40, "wall": 40}
# Side length (m); the strip's length. FAB strips are 8 × 5 cm (and 2 × 5 cm) clamped on the short sides.
DEFAULT_SIZE = {"cloth": 0.5, "stretch": 0.08, "sphere": 0.5, "wall": 0.5}
DEFAULT_FRICTION = 0.5  # cloth on the obstacles: cotton on wood or plastic lies around 0.3–0.6
DEFAULT_DAMPING = 1e-3  # s
# The plugin's implicit_drag: how much of the discrete step's drag -h K v (K the built-in isotropic
# share's stiffness) the cloth keeps: "full", or "critical" (each of the material's modes damped
# critically on the step's inertia, the rest given back: a woven's shear, 1e-3 of the share, rests
# in ~sqrt(k_b / k_t) steps instead of k_b / k_t; plugins/README.md, Split). Full by default:
# measured in session 53, critical settles the stretch strips (validate.stretch uses it) but drapes
# on contact get to rest later: the twill's Cusick drape coefficient 0.790 / 0.575 at 2.5 / 10 s
# against 0.547 / 0.397 with the full drag, both ~0.32 at 40 s (session 54: its membrane has no
# compressive tangent, and with the drag given back the sheet first shrinks in its plane; design
# notes §8); a cotton jersey's sphere drape, centre of mass at 2 s, 2.1 mm further from the
# converged one even at 0.0625 ms steps. (Under the anisotropic share, IMPLICIT_SHARES, it returns
# only the drag of modes without a tangent; the drapes run it so: validate.drape, session 55.)
IMPLICIT_DRAGS = ("full", "critical")
DEFAULT_IMPLICIT_DRAG = "full"
# The implicit share's membrane: "isotropic", MuJoCo's <elasticity> as compiled (stiff enough for
# the material's stiffest direction in every direction), or "anisotropic", the plugin's
# implicit_share key (half the material's tangent in each of its modes, written over MuJoCo's metric;
# split.anisotropic_share, plugins/README.md).
IMPLICIT_SHARES = ("isotropic", "anisotropic")
DEFAULT_IMPLICIT_SHARE = "isotropic"
# What `yarnfit export` (and a catalogue's exported cloth) writes for each scene unless told: the
# split `yarnfit validate` runs that kind of scene with, so that an exported scene is a validated
# one. The drapes' (yarnfit.validate.drape: criss-cross cells, constant-strain triangles, the
# anisotropic share, the drag of modes without a tangent given back) for the cloth, sphere and
# wall; the FAB strips' (yarnfit.validate.stretch: the isotropic share) for the strip. Criss-cross
# cells have a centre vertex each, so the drapes' scenes get 28 vertices a side: 1513 vertices and
# 2916 triangles, about the 1600 and 3042 of a 40 x 40 one-diagonal grid, at the same cost a step
# (the cotton twill dropped on the sphere: 17.7-17.8 ms against 16.9-18.4, session 59). Measured
# there, same vertices: hanging, the twill is at its rest shape by ~6 s under the drapes' split and
# still sinking at 12 s under the library's defaults; on the sphere it is down within 1 s against
# sliding down for 12 s (the isotropic share's drag on its shear; docs/design.md section 7).
DRAPES_SPLIT = {"mesh": "crisscross", "membrane": "triangle", "implicit_share": "anisotropic",
                "implicit_drag": "critical"}
STRIPS_SPLIT = {"mesh": "crisscross", "membrane": "triangle", "implicit_share": "isotropic",
                "implicit_drag": "critical"}
EXPORT_SPLIT = {"cloth": DRAPES_SPLIT, "stretch": STRIPS_SPLIT, "sphere": DRAPES_SPLIT, "wall": DRAPES_SPLIT}
EXPORT_RESOLUTION = {"cloth": 28, "stretch": DEFAULT_RESOLUTION["stretch"], "sphere": 28, "wall": 28}
