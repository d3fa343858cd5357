"""Benchmarks of yarnfit, one section per stage.

    python validation/bench.py [engine] [relax] [fit] [mujoco] [plugin_ridges] [plugin_nonlinear_stable_step]
                               [swatch] [swatch_frictionless] [drape_stable_step] [body] [shell_strip] [suite]

prints one ``name: value unit`` line per figure. Numba kernels are compiled (or loaded from the
on-disk cache) before anything is timed.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from typing import NamedTuple

import numba
import numpy as np

from yarnfit.engine import (
    Loads,
    QuasiStaticSolver,
    Rod,
    RodMaterial,
    RodModel,
    RodState,
    straight_points,
)
from yarnfit.engine import _kernels
from yarnfit.engine.contact import find_pairs
from yarnfit.engine.xpbd import _color_constraints
from yarnfit.mujoco import DRAPES_SPLIT
from yarnfit.tasks import one_core

# A polyester-like yarn: r = 0.1 mm, E = 3 GPa (docs/design.md §4 fibre table, mid-range).
YARN = RodMaterial(young_modulus=3e9, poisson_ratio=0.3, density=1380.0)
YARN_RADIUS = 1e-4


def report(name: str, value: float, unit: str) -> None:
    print(f"{name}: {value:.4g} {unit}", flush=True)


# -- engine ---------------------------------------------------------------------------------------


def projection_model(n_rods: int = 200, n_edges: int = 500) -> RodModel:
    """Parallel yarns, gently bent so that every projection does real work."""
    rods = []
    for k in range(n_rods):
        points = straight_points(0.05, n_edges, start=(0.0, 1e-3 * k, 0.0))
        points[:, 2] = 1e-3 * np.sin(points[:, 0] * 200.0)
        rods.append(Rod(points, YARN_RADIUS, YARN, straight=True, pinned_nodes=[0]))
    return RodModel.from_rods(rods)


def projections_per_second(model: RodModel, sweeps: int) -> float:
    """Constraint projections per second of the coloured XPBD sweep on Numba's current threads."""
    x = np.array(model.node_rest_position)
    q = np.array(model.edge_rest_quaternion)
    inv_mass = np.ascontiguousarray(model.node_inv_mass)
    inv_qmass = 0.25 * np.ascontiguousarray(model.edge_inv_inertia)
    lam_edge = np.zeros((model.n_edges, 3))
    lam_joint = np.zeros((model.n_joints, 3))
    args = (x, q, inv_mass, inv_qmass, model.arrays, lam_edge, lam_joint, 1e8, *_color_constraints(model))
    _kernels.project_rods(*args)  # compile or load from cache
    start = time.perf_counter()
    for _ in range(sweeps):
        _kernels.project_rods(*args)
    elapsed = time.perf_counter() - start
    return sweeps * (model.n_edges + model.n_joints) / elapsed


def crossing_bundle(n_per_layer: int = 10, n_edges: int = 100) -> tuple[RodModel, Loads]:
    """Two layers of ``n_per_layer`` yarns crossing at right angles (``2 n_per_layer n_edges``
    segments), pinned at their ends, the top layer pressed onto the bottom by a distributed load."""
    spacing = 1e-3
    length = (n_per_layer + 1) * spacing
    rods = []
    for k in range(n_per_layer):
        offset = (k + 1) * spacing - length / 2
        rods.append(Rod(straight_points(length, n_edges, start=(-length / 2, offset, 0.0)), YARN_RADIUS, YARN,
                        pinned_nodes=[0, -1]))
    for k in range(n_per_layer):
        offset = (k + 1) * spacing - length / 2
        rods.append(Rod(straight_points(length, n_edges, start=(offset, -length / 2, 2.5 * YARN_RADIUS),
                                        direction=(0.0, 1.0, 0.0)), YARN_RADIUS, YARN, pinned_nodes=[0, -1]))
    model = RodModel.from_rods(rods)
    loads = Loads.zeros(model)
    top = np.arange(model.rod_node_start[n_per_layer], model.n_nodes)
    loads.node_force[top, 2] = -2e-2 / (n_edges + 1)  # 20 mN per top yarn: most crossings carry load
    return model, loads


def tiled_bundles(copies: int) -> RodModel:
    """``copies`` copies of :func:`crossing_bundle` side by side along x, 2 mm apart."""
    bundle = crossing_bundle()[0]
    pitch = np.ptp(bundle.node_rest_position[:, 0]) + 2e-3
    rods = []
    for k in range(copies):
        for r in range(bundle.n_rods):
            nodes = bundle.rod_nodes(r)
            points = bundle.node_rest_position[nodes] + (k * pitch, 0.0, 0.0)
            rods.append(Rod(points, YARN_RADIUS, YARN))
    return RodModel.from_rods(rods)


def broad_phase_seconds(model: RodModel, repeats: int = 5) -> tuple[float, int]:
    """Best time of a static broad-phase query over the model (s) and the pairs it finds."""
    x = np.array(model.node_rest_position)
    n_pairs = len(find_pairs(model, x, YARN_RADIUS))
    best = math.inf
    for _ in range(repeats):
        start = time.perf_counter()
        find_pairs(model, x, YARN_RADIUS)
        best = min(best, time.perf_counter() - start)
    return best, n_pairs


def n_per_layer_crossings(model: RodModel, result) -> int:
    """Number of distinct yarn pairs touching (crossings carrying load)."""
    rods = model.edge_rod[result.contact_pairs.pairs]
    return len({tuple(sorted(pair)) for pair in rods.tolist()})


def bench_engine() -> None:
    threads = numba.config.NUMBA_NUM_THREADS
    model = projection_model()
    report("projection_model_constraints", model.n_edges + model.n_joints, "constraints")
    # The serial sweep is the coloured one on a single thread.
    numba.set_num_threads(1)
    report("projections_per_second_1core", projections_per_second(model, sweeps=20), "1/s")
    numba.set_num_threads(threads)
    report("projections_per_second_allcores", projections_per_second(model, sweeps=20), "1/s")
    report("threads", threads, "threads")

    # Broad phase on 1, 10 and 100 side-by-side copies of the 2000-segment bundle (constant density):
    # the time per segment should stay about flat.
    for copies in (1, 10, 100):
        model = tiled_bundles(copies)
        seconds, n_pairs = broad_phase_seconds(model)
        report(f"broad_phase_{model.n_edges}_segments_seconds", seconds, "s")
        report(f"broad_phase_{model.n_edges}_segments_pairs", n_pairs, "pairs")

    small_model, small_loads = crossing_bundle(2, 10)
    QuasiStaticSolver(small_model).solve(RodState.from_model(small_model), small_loads)  # compile or load
    model, loads = crossing_bundle()
    start = time.perf_counter()
    result = QuasiStaticSolver(model).solve(RodState.from_model(model), loads)
    elapsed = time.perf_counter() - start
    report("contact_2000_segments", model.n_edges, "segments")
    report("contact_2000_seconds", elapsed, "s")
    report("contact_2000_converged", float(result.converged), "bool")
    report("contact_2000_iterations", result.iterations, "iterations")
    report("contact_2000_force_residual", result.residual.force, "relative")
    report("contact_2000_torque_residual", result.residual.torque, "relative")
    report("contact_2000_penetration", result.residual.penetration, "relative")
    report("contact_2000_touching_pairs", len(result.contact_force), "pairs")
    report("contact_2000_crossings", n_per_layer_crossings(model, result), "crossings")


# -- relax ----------------------------------------------------------------------------------------


def bench_relax() -> None:
    """Phase-1 relaxation of the five presets: wall time (including the radius fixed point's extra
    relaxations) and the quality of the result. The first preset is relaxed once untimed so that
    every kernel is compiled."""
    import warnings

    from yarnfit.fabric import PRESETS, Fabric
    from yarnfit.relax import relax

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        relax(Fabric.preset(next(iter(PRESETS))))
        for name in PRESETS:
            result = relax(Fabric.preset(name))
            key = "relax_" + name.replace("-", "_")
            report(f"{key}_seconds", result.seconds, "s")
            report(f"{key}_nodes", result.model.n_nodes, "nodes")
            report(f"{key}_relaxations", result.relaxations, "relaxations")
            report(f"{key}_iterations", result.iterations, "iterations (last relaxation)")
            report(f"{key}_converged", int(result.converged), "bool")
            report(f"{key}_force_residual", result.residual.force, "relative")
            report(f"{key}_worst_overlap", result.penetration, "of the diameter")


# -- fit ------------------------------------------------------------------------------------------


def bench_fit() -> None:
    """Full shell fits (default sample design, every core) of the five presets (knits loaded with
    friction, as by default) and of the HYLC stockinette (frictionless): wall time by stage, the
    slowest sample, the engineering constants and R² per sample family. A small fit runs first,
    untimed, so that every kernel is compiled."""
    import warnings
    from pathlib import Path

    from yarnfit.fabric import PRESETS, Fabric
    from yarnfit.fabric_fit import fit_fabric
    from yarnfit.fibers import get_fiber
    from yarnfit.samples import design_size

    stockinette = Path(__file__).parents[1] / "tests" / "data" / "hylc" / "stockinette.pyp"
    fabrics = [Fabric.preset(name) for name in PRESETS]
    fabrics.append(Fabric(name="stockinette", fiber=get_fiber("polyester"), pattern_file=stockinette))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit_fabric(fabrics[0], samples=design_size(1), workers=1)
        for fabric in fabrics:
            # The presets as `yarnfit fit` fits them (knits loaded with friction); the stockinette
            # as the paper and HYLC solve it, frictionless: its time per sample is HYLC's benchmark.
            fitted = fit_fabric(fabric, friction=False if fabric.name == "stockinette" else None)
            key = "fit_" + fabric.name.replace("-", "_")
            seconds = fitted.seconds
            report(f"{key}_seconds", sum(seconds.values()), "s")
            for stage in ("relax", "homogenize", "fit"):
                report(f"{key}_{stage}_seconds", seconds[stage], "s")
            report(f"{key}_slowest_sample_seconds", max(r.seconds for r in fitted.samples), "s (one core)")
            report(f"{key}_mean_sample_seconds", sum(r.seconds for r in fitted.samples) / len(fitted.samples),
                   "s (one core)")
            report(f"{key}_samples_fitted", len(fitted.fit.used), f"of {len(fitted.samples)}")
            for name, value in fitted.material.engineering().items():
                report(f"{key}_{name}", value, "")
            for family, quality in fitted.fit.families.items():
                if quality["samples"]:
                    report(f"{key}_r2_{family}", quality["r2"], "")
            signed = fitted.fit.signed_fit  # the material's bending unless the fit's notes say why not
            if signed is not None:
                h3 = fitted.material.thickness**3
                for name, value in signed.parameters.items():
                    report(f"{key}_signed_{name}_nm", h3 * value, "" if fitted.fit.bending == "signed" else "(not used)")
                for family, quality in fitted.fit.linear_families.items():
                    if family.endswith("_bend") and quality["samples"]:
                        report(f"{key}_symmetric_r2_{family}", quality["r2"], "")
        # The stockinette's samples once more on one worker, its own relaxation reused: the
        # figures above run every core at once, and a sample then shares the machine's caches and
        # memory with another (10–15 % slower on 2 cores); this is one core to itself.
        alone = fit_fabric(fabrics[-1], workers=1, relaxed=fitted.relaxed, friction=False)
        seconds = sum(r.seconds for r in alone.samples)
        report("fit_stockinette_one_worker_mean_sample_seconds", seconds / len(alone.samples),
               "s (one core, nothing else running)")
        # The same over the design's samples other than its compressions (sampled since session 56,
        # cheaper than the mean: 0.45 s each against 0.61), the design the figure was quoted for before.
        others = [r for r in alone.samples if not r.spec.compressed]
        report("fit_stockinette_one_worker_mean_sample_seconds_without_compression",
               sum(r.seconds for r in others) / len(others), f"s (one core; {len(others)} samples)")
        # The same run in Newton iterations, which the machine does not change (its time per sample
        # moved by 15 % between two quiet runs of the same solver, sessions 53 and 54): a change to the
        # solver's path shows here, one to its cost per iteration in the next figure.
        iterations = sum(r.iterations for r in alone.samples)
        report("fit_stockinette_one_worker_newton_iterations", iterations, "")
        report("fit_stockinette_one_worker_ms_per_iteration", 1e3 * seconds / iterations, "ms (one core)")


# -- mujoco ---------------------------------------------------------------------------------------

# Simulated time per measured run (s): long enough to average over the cloth's swing or landing.
MUJOCO_BENCH_SECONDS = 0.5


def _without_plugin(spec):
    """A copy of an exported scene with the yarnfit.shell plugin removed: the built-in isotropic
    part alone, same mesh, masses, contacts, integrator and Δt."""
    bare = spec.copy()
    for body in bare.bodies:
        if body.plugin.active:
            body.plugin.active = False
    for plugin in list(bare.plugins):
        bare.delete(plugin)
    return bare


def _timed_steps(model, steps: int, keep_every: int, name: str) -> tuple[float, list]:
    """Step ``model`` from its initial state, 10 steps untimed then ``steps`` timed one call each
    (the same loop for every variant compared), keeping ``(qpos, qvel)`` every ``keep_every``
    steps: ``(ms per step, states)``. Warns on stderr if MuJoCo flagged a bad acceleration."""
    import mujoco

    data = mujoco.MjData(model)
    mujoco.mj_step(model, data, nstep=10)
    states = []
    start = time.perf_counter()
    for step in range(steps):
        mujoco.mj_step(model, data)
        if step % keep_every == 0:
            states.append((data.qpos.copy(), data.qvel.copy()))
    seconds = time.perf_counter() - start
    if data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number:
        print(f"warning: {name} became unstable", file=sys.stderr)
    return 1e3 * seconds / steps, states


def _passive_ms(model, states: list) -> float:
    """Mean wall time (ms) of MuJoCo's passive forces (``mj_passive``, where the plugin computes) at
    ``states`` (``(qpos, qvel)`` pairs), each after a forward pass, 20 calls a state."""
    import mujoco

    data = mujoco.MjData(model)
    total = 0.0
    for qpos, qvel in states:
        data.qpos[:], data.qvel[:] = qpos, qvel
        mujoco.mj_forward(model, data)
        start = time.perf_counter()
        for _ in range(20):
            mujoco.mj_passive(model, data)
        total += (time.perf_counter() - start) / 20
    return 1e3 * total / len(states)


def bench_mujoco() -> None:
    """A 40×40 cloth of the ``cloth`` and ``sphere`` scenes under ``build_scene``'s library defaults
    (one-diagonal grid, node strains, isotropic share, full drag: what ``yarnfit export`` wrote until
    session 59, kept so the figures compare across sessions) with the scene's integrator, Δt and
    solver, with the plugin and without it (the same scene, plugin removed), the plugin's own
    compute at the same states (mj_passive with the plugin minus without it), and the scene with
    the plugin under the other constraint solver; then each scene as ``yarnfit export`` writes it
    (:func:`yarnfit.mujoco.scenes.export_options`: the drapes' split at 28 criss-cross vertices a
    side, about the grid's vertex count) in the same run, with its cost over the library defaults'."""
    from pathlib import Path

    import mujoco

    from yarnfit.mujoco.scenes import SOLVER_ENUM, SOLVER_LABEL, ClothMaterial, build_scene, export_options

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from fabric_shell import FABRIC  # a realistic medium-weight woven

    material = ClothMaterial("medium woven", FABRIC, 0.2)
    for scene in ("cloth", "sphere"):
        built = build_scene(material, scene, resolution=40)
        models = {"with": built.spec.compile(), "without": _without_plugin(built.spec).compile()}
        steps = round(MUJOCO_BENCH_SECONDS / models["with"].opt.timestep)
        ms_per_step, states = {}, []
        for variant, model in models.items():
            ms_per_step[variant], kept = _timed_steps(model, steps, keep_every=steps // 10, name=f"{scene} {variant}")
            if variant == "with":
                states = kept
        plugin_ms = _passive_ms(models["with"], states) - _passive_ms(models["without"], states)
        key = f"mujoco_{scene}_40x40"
        integrator = mujoco.mjtIntegrator(models["with"].opt.integrator).name.removeprefix("mjINT_").lower()
        solver = SOLVER_LABEL[models["with"].opt.solver]
        info = f"{models['with'].opt.timestep:g} s step, {integrator}, {solver}"
        report(f"{key}_ms_per_step_with_plugin", ms_per_step["with"], f"ms ({info})")
        report(f"{key}_ms_per_step_without_plugin", ms_per_step["without"], "ms")
        report(f"{key}_plugin_compute_ms", plugin_ms, "ms per step")
        report(f"{key}_plugin_compute_fraction", plugin_ms / ms_per_step["without"], "of the step without it")
        # The other solver on the same scene, in the same run (the scenes' DEFAULT_SOLVER: CG where
        # the cloth touches something).
        other = next(name for name, value in SOLVER_ENUM.items() if value != models["with"].opt.solver)
        model = build_scene(material, scene, resolution=40, solver=other).spec.compile()
        other_ms, _ = _timed_steps(model, steps, keep_every=steps // 10, name=f"{scene} {other}")
        report(f"{key}_ms_per_step_with_plugin_{other}", other_ms,
               f"ms ({other_ms / ms_per_step['with']:.2f}× the default's)")
        options = export_options(scene)
        exported = build_scene(material, scene, **options).spec.compile()
        export_ms, _ = _timed_steps(exported, steps, keep_every=steps // 10, name=f"{scene} exported")
        report(f"mujoco_{scene}_exported_ms_per_step", export_ms,
               f"ms ({options['resolution']} x {options['resolution']} {options['mesh']}, {exported.nflexvert} "
               f"vertices; {export_ms / ms_per_step['with']:.2f}× the library defaults' at 40 x 40)")


# -- plugin_ridges -------------------------------------------------------------------------------

# The splits the plugin's ridge cost is measured under: build_scene's library defaults (grid, node
# strains, isotropic share, full drag: what yarnfit export wrote until session 59) and the drapes'
# (yarnfit.mujoco.DRAPES_SPLIT, what it writes for the cloth now: criss-cross cells, triangle
# strains, the anisotropic share, the drag given back, whose returned metric follows the ridges
# engaged in each triangle). Both at 40 x 40, the drapes' with twice the vertices.
RIDGE_BENCH_SPLITS = {"library": {}, "drapes": DRAPES_SPLIT}


def bench_plugin_ridges() -> None:
    """What a fitted strain-stiffening membrane costs the plugin: the cotton twill fitted as
    ``yarnfit fit`` fits it (its ridges, and the directions they lie along), hung as a 40 × 40 cloth
    (``--scene cloth``) under the library's split and the drapes', stepped 0.5 s with the plugin and
    without it; the plugin's own compute per step (mj_passive with it less without it, as section
    ``mujoco``) with the fit's ridge membrane and with its linear membrane (``--linear``)."""
    import tempfile
    import warnings
    from pathlib import Path

    import numpy as np

    from yarnfit.fabric import Fabric
    from yarnfit.fabric_fit import fit_fabric
    from yarnfit.mujoco.scenes import ClothMaterial, build_scene

    with warnings.catch_warnings(), tempfile.TemporaryDirectory() as folder:
        warnings.simplefilter("ignore")
        fitted = fit_fabric(Fabric.preset("cotton-twill"))
        path = Path(folder) / "cotton-twill.json"
        fitted.write(path)
        ridges = np.array(fitted.material.nonlinear.ridges, dtype=float).reshape(-1, 5)
        report("plugin_ridges_cotton_twill_ridges", len(ridges), "ridges")
        report("plugin_ridges_cotton_twill_directions", len(np.unique(ridges[:, :3], axis=0)), "directions")
        for split_name, split in RIDGE_BENCH_SPLITS.items():
            for membrane, linear in (("ridges", False), ("linear", True)):
                material = ClothMaterial.from_file(path, None, linear=linear)
                built = build_scene(material, "cloth", resolution=40, **split)
                with_plugin, without = built.spec.compile(), _without_plugin(built.spec).compile()
                steps = round(MUJOCO_BENCH_SECONDS / with_plugin.opt.timestep)
                ms, states = _timed_steps(with_plugin, steps, keep_every=steps // 10, name=f"{split_name} {membrane}")
                plugin_ms = _passive_ms(with_plugin, states) - _passive_ms(without, states)
                key = f"plugin_ridges_{split_name}_split_{membrane}"
                report(f"{key}_ms_per_step", ms, "ms (40 x 40 cloth, one core)")
                report(f"{key}_plugin_compute_ms", plugin_ms, "ms per step")


# -- plugin_nonlinear_stable_step -----------------------------------------------------------------

# The ridge membrane given to the woven for this section: its S as the base, and along weft and warp
# tension ridges of 2 S_dd at 2 % and 5 %, so the tangent is 5 S_dd from 5 % (and at 10 %);
# compression and shear unchanged.
STIFFENING_KNOTS = (0.02, 0.05)
STIFFENING_STEP = 2.0
# Cell sizes (m) of the exported 0.5 m hanging cloth: 26 and 51 vertices per side.
STABLE_STEP_CELLS = (0.02, 0.01)
# Simulated time per trial (s). The cloth falls from horizontal and swings; its pinned corners are
# yanked at each turn, and stiffened runs near their limit diverged at 0.33, 0.85, 1.0 and 1.3 s
# (2 cm cells). Near the limit the outcome also depends on the exact step (a step 1e-4 larger than
# one that survived 2 s diverged at 1.3 s), hence the grid below rather than a bisection.
STABLE_STEP_SECONDS = 2.0
# Steps tried: DEFAULT_TIMESTEP × STABLE_STEP_GRID^k, from the start up while stable or down until
# stable; the answer is a grid step that ran stably and its neighbour above that did not (19 %
# apart).
STABLE_STEP_GRID = 2.0**0.25
STABLE_STEP_MAX = 0.016  # s: 16× the export default; the swing is not resolved beyond it anyway
STABLE_STEP_MIN = 1e-6  # s
# A run fails on MuJoCo's bad-QACC warning, a non-finite position, a vertex faster than this (m/s):
# free fall from the cloth's 0.6 m gives 3.4 m/s and its whipping corners reached 7–11 m/s in
# stable runs, while a diverging run passes 100 m/s within tens of steps of leaving that range ...
STABLE_STEP_SPEED_LIMIT = 50.0
# ... or a weft or warp Green strain above this: stable runs peak at 5–7 % (2 cm cells) and 11 %
# (1 cm, the pinned corners' point load) at 1 ms; at 8 ms (2 cm) the StVK cloth stays clear of
# bad QACC but its corner triangles pass 30 % (660 % at 16 ms): a failed step, not cloth.
STABLE_STEP_STRAIN_LIMIT = 0.3


class _Hang(NamedTuple):
    """One trial: whether it ran stably, what failed (empty if nothing), the largest vertex speed
    (m/s) and weft or warp Green strain seen."""

    stable: bool
    failure: str
    speed: float
    strain: float


def _ridged(shell):
    """``shell`` with the section's ridge membrane (STIFFENING_KNOTS, STIFFENING_STEP)."""
    import dataclasses

    from yarnfit.shell import RidgeMembrane

    ridges = tuple((1.0, 0.0, 0.0, knot, STIFFENING_STEP * shell.s00) for knot in STIFFENING_KNOTS)
    ridges += tuple((0.0, 1.0, 0.0, knot, STIFFENING_STEP * shell.s11) for knot in STIFFENING_KNOTS)
    return dataclasses.replace(shell, nonlinear=RidgeMembrane((shell.s00, shell.s01, shell.s11, shell.s22), ridges))


def _hanging_cloth(material, cell: float, timestep: float, damping: float, stiffening_bound: float):
    """The exported cloth scene (built-in split covering the ridges up to ``stiffening_bound``,
    discrete integrator) at ``cell`` spacing."""
    from yarnfit.mujoco.scenes import DEFAULT_SIZE, build_scene, compile_quietly

    size = DEFAULT_SIZE["cloth"]
    built = build_scene(material, "cloth", resolution=round(size / cell) + 1, timestep=timestep, damping=damping,
                        stiffening_bound=stiffening_bound)
    return compile_quietly(built.spec)


def _hang(model, seconds: float) -> _Hang:
    """Step ``model`` for ``seconds`` and watch it (the cloth flat at qpos0, weft along world x)."""
    import mujoco

    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    rest = data.flexvert_xpos.copy()
    triangles = model.flex_elem.reshape(-1, 3)
    rest_edges = np.stack([rest[triangles[:, 1], :2] - rest[triangles[:, 0], :2],
                           rest[triangles[:, 2], :2] - rest[triangles[:, 0], :2]], axis=2)  # (T, 2, 2)
    rest_inverse = np.linalg.inv(rest_edges)
    bodies = np.unique(model.flex_vertbodyid)
    bodies = bodies[model.body_dofnum[bodies] == 3]
    dofs = model.body_dofadr[bodies][:, None] + np.arange(3)
    warning = int(mujoco.mjtWarning.mjWARN_BADQACC)
    speed, strain = 0.0, 0.0
    for step in range(round(seconds / model.opt.timestep)):
        mujoco.mj_step(model, data)
        when = f"at {(step + 1) * model.opt.timestep:.2f} s"  # MuJoCo resets data.time on bad QACC
        if data.warning[warning].number:
            return _Hang(False, f"bad QACC {when}", speed, strain)
        if not np.all(np.isfinite(data.qpos)):
            return _Hang(False, f"non-finite {when}", speed, strain)
        speed = max(speed, float(np.sqrt((data.qvel[dofs] ** 2).sum(axis=1)).max()))
        x = data.flexvert_xpos
        edges = np.stack([x[triangles[:, 1]] - x[triangles[:, 0]], x[triangles[:, 2]] - x[triangles[:, 0]]], axis=2)
        F = edges @ rest_inverse  # (T, 3, 2): columns along weft and warp
        strain = max(strain, 0.5 * (float((F**2).sum(axis=1).max()) - 1.0))
        if speed > STABLE_STEP_SPEED_LIMIT:
            return _Hang(False, f"speed {speed:.3g} m/s {when}", speed, strain)
        if strain > STABLE_STEP_STRAIN_LIMIT:
            return _Hang(False, f"strain {strain:.3g} {when}", speed, strain)
    return _Hang(True, "", speed, strain)


def _largest_stable_step(material, cell: float, damping: float, stiffening_bound: float, start: float):
    """Scan the step grid from the grid step nearest ``start`` (s). Returns the largest stable step
    found (s, None if none down to the minimum) with its trial, and the failing step above it (s,
    inf if every step up to the maximum ran) with its trial."""
    from yarnfit.mujoco import DEFAULT_TIMESTEP

    def trial(k):
        timestep = DEFAULT_TIMESTEP * STABLE_STEP_GRID**k
        result = _hang(_hanging_cloth(material, cell, timestep, damping, stiffening_bound), STABLE_STEP_SECONDS)
        print(f"  {cell * 100:g} cm, damping {damping:g} s, {material.name}, cover {stiffening_bound:g}: "
              f"{timestep * 1e3:.4g} ms {result.failure or 'stable'}", file=sys.stderr, flush=True)  # progress
        return timestep, result

    k = round(math.log(start / DEFAULT_TIMESTEP, STABLE_STEP_GRID))
    timestep, result = trial(k)
    stable = unstable = None
    if result.stable:
        stable = (timestep, result)
        while DEFAULT_TIMESTEP * STABLE_STEP_GRID ** (k + 1) <= STABLE_STEP_MAX:
            k += 1
            timestep, result = trial(k)
            if not result.stable:
                unstable = (timestep, result)
                break
            stable = (timestep, result)
    else:
        unstable = (timestep, result)
        while DEFAULT_TIMESTEP * STABLE_STEP_GRID ** (k - 1) >= STABLE_STEP_MIN:
            k -= 1
            timestep, result = trial(k)
            if result.stable:
                stable = (timestep, result)
                break
            unstable = (timestep, result)
    return stable, unstable


def bench_plugin_nonlinear_stable_step() -> None:
    """Largest stable time step of the exported hanging cloth (0.5 m, two corners pinned, built-in
    split, discrete integrator) of the realistic woven of tests/fabric_shell.py, as StVK and with a
    ridge membrane (tangents 5× from 5 % weft/warp strain), the latter with the export's split
    (the built-in share covering half the ridges' largest tangent within ±DEFAULT_STIFFENING_BOUND)
    and with a split that covers S alone; at 2 cm and 1 cm cells, with the export's damping time
    and without damping. The ridges' forces, and their damping, are explicit: nothing of them is in
    the implicit built-in part but what the split's cover puts there."""
    from pathlib import Path

    from yarnfit.mujoco import DEFAULT_DAMPING, DEFAULT_TIMESTEP
    from yarnfit.mujoco.scenes import ClothMaterial
    from yarnfit.mujoco.split import DEFAULT_STIFFENING_BOUND

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from fabric_shell import FABRIC  # a realistic medium-weight woven

    variants = {"stvk": (ClothMaterial("stvk", FABRIC, 0.2), DEFAULT_STIFFENING_BOUND),
                "ridges": (ClothMaterial("ridges", _ridged(FABRIC), 0.2), DEFAULT_STIFFENING_BOUND),
                "ridges_no_cover": (ClothMaterial("ridges", _ridged(FABRIC), 0.2), 0.0)}
    for knot in STIFFENING_KNOTS:
        report(f"plugin_nonlinear_ridge_at_{knot * 100:g}_percent", STIFFENING_STEP, "× s00 (weft), × s11 (warp)")
    report("plugin_nonlinear_trial_seconds", STABLE_STEP_SECONDS, "s simulated per trial")
    found = {}  # (damping, variant) -> (cell, largest stable step) at the coarser cell
    for cell in STABLE_STEP_CELLS:
        for damping in (DEFAULT_DAMPING, 0.0):
            for variant, (material, bound) in variants.items():
                key = f"plugin_nonlinear_{cell * 100:g}cm_{variant}_damping_{damping * 1e3:g}ms"
                # From the export's step, or from the coarser cloth's limit scaled with the cell (as
                # an explicit elastic limit scales): fewer trials where they are expensive.
                coarser = found.get((damping, variant))
                start = DEFAULT_TIMESTEP if coarser is None else coarser[1] * cell / coarser[0]
                start_time = time.perf_counter()
                stable, unstable = _largest_stable_step(material, cell, damping, bound, start)
                if unstable is None:
                    above = f"stable at every grid step up to {stable[0] * 1e3:.3g} ms"
                else:
                    above = f"{unstable[0] * 1e3:.3g} ms failed: {unstable[1].failure}"
                if stable is None:
                    report(f"{key}_stable_step", 0.0, f"ms (none down to {STABLE_STEP_MIN * 1e3:g} ms; {above})")
                    continue
                found[damping, variant] = (cell, stable[0])
                report(f"{key}_stable_step", stable[0] * 1e3, f"ms ({above})")
                report(f"{key}_largest_speed", stable[1].speed, "m/s (at that step)")
                report(f"{key}_largest_strain", stable[1].strain, "Green strain, weft or warp (at that step)")
                report(f"{key}_search_seconds", time.perf_counter() - start_time, "s")


# -- drape_stable_step ----------------------------------------------------------------------------

# Cell sizes (m) of the 0.3 m sphere drape (the validate scene's swatch on its 9 cm sphere): 16, 31
# and 61 vertices per side.
DRAPE_CELLS = (0.02, 0.01, 0.005)
# Steps tried (s), from the export's 1 ms up while stable, down while not.
DRAPE_STEPS = (0.25e-3, 0.5e-3, 1e-3, 2e-3, 4e-3, 8e-3, 16e-3)
# Simulated time per trial (s). Failures seen come within 0.35 s (bending modes blow up in free
# fall, or the landing); 0.5 cm trials run 1 s, since a step costs ~0.2 s there with implicit bending.
DRAPE_SECONDS = {0.02: 2.0, 0.01: 2.0, 0.005: 1.0}
# A trial fails on bad QACC, a non-finite position, or a gain of mechanical energy (kinetic plus
# gravitational; the elastic part only stores) beyond semi-implicit Euler's own free-fall drift
# (½ g² Δt t per unit mass) by more than the energy of a 5 mm drop: a diverging run gains metres.
DRAPE_GAIN_DROP = 5e-3  # m


class _Drape(NamedTuple):
    """One drape trial: stable, what failed, centre-of-mass height at the end (m), ms per step."""

    stable: bool
    failure: str
    height: float
    ms_per_step: float


def _drape_trial(material, cell: float, timestep: float, seconds: float, split: dict) -> _Drape:
    import mujoco

    from yarnfit.mujoco.scenes import build_scene, compile_quietly

    size = 0.3
    built = build_scene(material, "sphere", resolution=round(size / cell) + 1, size=size, timestep=timestep, **split)
    model = compile_quietly(built.spec)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    bodies = np.unique(model.flex_vertbodyid)
    bodies = bodies[model.body_dofnum[bodies] == 3]
    dofs = model.body_dofadr[bodies][:, None] + np.arange(3)
    mass = model.body_mass[bodies]
    g = 9.81

    def energy() -> float:
        return float(0.5 * (mass * (data.qvel[dofs] ** 2).sum(1)).sum() + g * (mass * data.xpos[bodies, 2]).sum())

    start_energy, steps = energy(), round(seconds / timestep)
    start = time.perf_counter()
    for step in range(1, steps + 1):
        mujoco.mj_step(model, data)
        when = f"at {step * timestep:.2f} s"
        if data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number:
            return _Drape(False, f"bad QACC {when}", math.nan, math.nan)
        if not np.all(np.isfinite(data.qpos)):
            return _Drape(False, f"non-finite {when}", math.nan, math.nan)
        allowed = mass.sum() * g * (0.5 * g * timestep * step * timestep + DRAPE_GAIN_DROP)
        if energy() - start_energy > allowed:
            return _Drape(False, f"energy gain {when}", math.nan, math.nan)
    elapsed = time.perf_counter() - start
    height = float((mass * data.xpos[bodies, 2]).sum() / mass.sum())
    return _Drape(True, "", height, 1e3 * elapsed / steps)


def bench_drape_stable_step() -> None:
    """Largest stable step of the sphere drape (0.3 m swatch, 9 cm sphere, discrete, Newton) of the
    five presets at 2, 1 and 0.5 cm cells, before issue 15 (all bending explicit in the plugin, the
    built-in part covering half of S, constant-strain triangles), with the built-in part also
    bending and covering the stiffening up to split.DEFAULT_STIFFENING_BOUND ("triangle"), now (that,
    with node-smoothed membrane strains), and now with the soft modes' drag given back
    ("critical_drag": the plugin's implicit_drag="critical", not the export's default), and with the
    anisotropic implicit share (the plugin's implicit_share, half the material's tangent in each
    mode: "anisotropic" with node strains, "anisotropic_triangle" with constant-strain triangles),
    with ms per step and per simulated second at that step and the centre of mass's height at the
    end (a step that drags the drape shows as a higher cloth). Long: hours at 0.5 cm."""
    import tempfile
    import warnings
    from pathlib import Path

    from yarnfit.fabric import PRESETS, Fabric
    from yarnfit.fabric_fit import fit_fabric
    from yarnfit.mujoco.scenes import ClothMaterial

    variants = {"before": {"implicit_bending": False, "stiffening_bound": 0.0, "membrane": "triangle"},
                "triangle": {"membrane": "triangle"}, "now": {}, "critical_drag": {"implicit_drag": "critical"},
                "anisotropic": {"implicit_share": "anisotropic"},
                "anisotropic_triangle": {"implicit_share": "anisotropic", "membrane": "triangle"}}
    for name in PRESETS:
        with warnings.catch_warnings(), tempfile.TemporaryDirectory() as folder:
            warnings.simplefilter("ignore")
            # Through the material file, as `yarnfit export` reads it (shell and areal density).
            material = ClothMaterial.from_file(fit_fabric(Fabric.preset(name)).write(Path(folder) / f"{name}.json"))
        for cell in DRAPE_CELLS:
            for variant, split in variants.items():
                key = f"drape_{name.replace('-', '_')}_{cell * 100:g}cm_{variant}"
                k = DRAPE_STEPS.index(1e-3)
                trials = {}

                def trial(index):
                    if index not in trials:
                        trials[index] = _drape_trial(material, cell, DRAPE_STEPS[index], DRAPE_SECONDS[cell], split)
                        print(f"  {key}: {DRAPE_STEPS[index] * 1e3:g} ms {trials[index].failure or 'stable'}",
                              file=sys.stderr, flush=True)  # progress
                    return trials[index]

                if trial(k).stable:
                    while k + 1 < len(DRAPE_STEPS) and trial(k + 1).stable:
                        k += 1
                else:
                    while k >= 0 and not trial(k).stable:
                        k -= 1
                if k < 0:
                    report(f"{key}_stable_step", 0.0, f"ms (none down to {DRAPE_STEPS[0] * 1e3:g} ms)")
                    continue
                best, step = trials[k], DRAPE_STEPS[k]
                above = trials.get(k + 1)
                report(f"{key}_stable_step", step * 1e3,
                       f"ms ({above.failure if above else 'largest step tried'} above)")
                report(f"{key}_ms_per_step", best.ms_per_step, "ms")
                report(f"{key}_s_per_simulated_s", best.ms_per_step / (step * 1e3), "s")
                report(f"{key}_final_height", best.height, f"m (centre of mass after {DRAPE_SECONDS[cell]:g} s)")


# -- swatch ---------------------------------------------------------------------------------------


def bench_swatch(friction: bool = True) -> None:
    """The explicit yarn-level stretch test's strips at the suite's full size (``yarnfit validate``,
    node budget included), 2 / 5 / 10 % on one core, with the fibre's friction at the yarn contacts
    as the suite pulls them (:mod:`yarnfit.engine.friction`; section ``swatch_frictionless``
    without): nodes, and per strain the solve's wall time, Newton iterations (over every lagged
    pass), the pull (N/m), and with friction the load steps it was reached in
    (:data:`yarnfit.engine.lagged.FRICTION_STRAIN_STEP` apart), the slowest step's wall time and
    the lagged passes, and the middle half's pull where the strip is uniform
    (:func:`yarnfit.validate.strip.cut_forces`, with its middle's strain). Cotton jersey along the
    weft, cotton twill along weft and warp (the warp strip, 1819 nodes, is the presets' largest; a
    satin is cut to the node budget). ``validation/swatch_convergence.py`` gives the strips of
    other sizes."""
    import warnings

    from yarnfit.fabric import Fabric
    from yarnfit.relax import relax
    from yarnfit.validate.swatch import stretch_repeat

    with one_core(), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for name, directions in (("cotton-jersey", ("weft",)), ("cotton-twill", ("weft", "warp"))):
            fabric = Fabric.preset(name)
            relaxed = relax(fabric)
            out = stretch_repeat(relaxed.model, relaxed.state.node_position, relaxed.yarn.section(), name=name,
                                 directions=directions, friction=fabric.fiber.friction if friction else 0.0)
            for direction in directions:
                curve = out["directions"][direction]
                key = f"swatch{'' if friction else '_frictionless'}_{name.replace('-', '_')}_{direction}"
                report(f"{key}_nodes", curve["nodes"], "nodes")
                for point in curve["points"][1:]:
                    percent = f"{100 * point['strain']:g}pct"
                    report(f"{key}_{percent}_seconds", point["seconds"], "s (one core)")
                    report(f"{key}_{percent}_iterations", point["iterations"], "iterations")
                    report(f"{key}_{percent}_converged", int(point["converged"]), "bool")
                    report(f"{key}_{percent}_force", point["force_n_per_m"], "N/m")
                    report(f"{key}_{percent}_middle_force", point["middle_force_n_per_m"],
                           f"N/m (middle half, its strain {100 * point['mid_strain']:.3g} %)"
                           if point["mid_strain"] is not None else "N/m (middle half)")
                    if friction:
                        report(f"{key}_{percent}_load_steps", point["load_steps"], "steps")
                        report(f"{key}_{percent}_slowest_step_seconds", point["slowest_step_seconds"], "s (one core)")
                        report(f"{key}_{percent}_friction_passes", point["friction_passes"], "passes")


def bench_body() -> None:
    """The full-body scene (``yarnfit.validate.body``), quick and full, with the plugin and with
    MuJoCo's native isotropic elasticity alone (the same garments, sewn on the same way), on the
    medium woven: milliseconds of stepping per simulated second, the real-time factor, the
    plugin's cost over the native scene's (measured in the same run), and the sewing's wall time."""
    from pathlib import Path

    from yarnfit.mujoco.scenes import ClothMaterial
    from yarnfit.validate.body import run_body

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from fabric_shell import FABRIC  # a realistic medium-weight woven

    material = ClothMaterial("medium woven", FABRIC, 0.2)
    for quick in (True, False):
        scale = "quick" if quick else "full"
        cost = {}
        for native in (False, True):
            variant = "native" if native else "plugin"
            result = run_body(material, quick=quick, native=native)
            if not result.stable:
                print(f"warning: body {scale} {variant} was not stable", file=sys.stderr)
            cost[variant] = 1e3 * result.wall_time_s / result.simulated_s
            vertices = sum(g["vertices"] for g in result.garments.values())
            report(f"body_{scale}_{variant}_ms_per_simulated_s", cost[variant],
                   f"ms ({vertices} garment vertices, {result.timestep_s * 1e3:g} ms steps)")
            report(f"body_{scale}_{variant}_real_time_factor", result.simulated_s / result.wall_time_s, "x")
            report(f"body_{scale}_{variant}_sewing_s", result.sewing_wall_time_s, "s")
        report(f"body_{scale}_plugin_over_native", cost["plugin"] / cost["native"], "x")


def bench_shell_strip() -> None:
    """The stretch scene's quasi-static reference (``stretch.quasi_static_forces``): the shell
    strips of its six strips (8 × 5 and 2 × 5 cm along weft, warp and bias) extrapolated from
    :data:`~yarnfit.validate.stretch.QUASI_STATIC_ROWS` rows, through every strain level, for the
    cotton twill and the polyester satin (fitted here with the default design): wall time per strip
    on one core, Newton iterations, and whether every load step converged."""
    import warnings

    from yarnfit.fabric import Fabric
    from yarnfit.fabric_fit import fit_fabric
    from yarnfit.validate import DIRECTIONS
    from yarnfit.validate.shell_strip import shell_strip_limit
    from yarnfit.validate.stretch import QUASI_STATIC_ROWS, STRAIN_LEVELS, STRIPS

    for preset in ("cotton-twill", "polyester-satin"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            shell = fit_fabric(Fabric.preset(preset)).material
        key = "shell_strip_" + preset.replace("-", "_")
        shell_strip_limit(shell, 0.0, 0.02, 0.01, [0.002], rows=4)  # compile or load the kernels
        total = 0.0
        for strip, (length, width) in STRIPS.items():
            for direction, angle in DIRECTIONS.items():
                start = time.perf_counter()
                with one_core():
                    curve = shell_strip_limit(shell, angle, length, width, STRAIN_LEVELS,
                                              rows=QUASI_STATIC_ROWS[False])
                seconds = time.perf_counter() - start
                total += seconds
                report(f"{key}_{strip}_{direction}_seconds", seconds,
                       f"s ({sum(s.iterations for s in curve.states)} Newton iterations, "
                       f"{'converged' if curve.converged else 'NOT converged'})")
        report(f"{key}_seconds", total, f"s (six strips, {'/'.join(map(str, curve.rows))} rows, one core)")


def bench_suite() -> None:
    """``yarnfit validate``'s full suite on the cotton twill (fitted here with the default design):
    wall time of each scene and of the whole suite with the scenes side by side on every core (the
    command line's default) and one after another in this process, in the same run, and their
    ratio (issue 14's target: the full suite of one material under 10 minutes). About 17 minutes on
    2 cores."""
    import tempfile
    import warnings
    from pathlib import Path

    from yarnfit.fabric import Fabric
    from yarnfit.fabric_fit import fit_fabric
    from yarnfit.tasks import LocalPool
    from yarnfit.validate.suite import run_suite

    with warnings.catch_warnings(), tempfile.TemporaryDirectory() as folder:
        warnings.simplefilter("ignore")
        material = fit_fabric(Fabric.preset("cotton-twill")).write(Path(folder) / "cotton-twill.json")
        total = {}
        for variant, workers in (("side_by_side", None), ("one_after_another", 1)):
            start = time.perf_counter()
            with LocalPool(workers) as backend:
                summary, _ = run_suite(material, logs=Path(folder) / variant, backend=backend)
            total[variant] = time.perf_counter() - start
            for scene, seconds in summary["wall_seconds"].items():
                report(f"suite_cotton_twill_{variant}_{scene}_seconds", seconds, "s")
            report(f"suite_cotton_twill_{variant}_seconds", total[variant],
                   f"s ({backend.workers} worker{'s' if backend.workers > 1 else ''})")
        report("suite_cotton_twill_side_by_side_over_one_after_another",
               total["side_by_side"] / total["one_after_another"], "x")


SECTIONS = {"engine": bench_engine, "relax": bench_relax, "fit": bench_fit, "mujoco": bench_mujoco,
            "plugin_ridges": bench_plugin_ridges,
            "plugin_nonlinear_stable_step": bench_plugin_nonlinear_stable_step, "swatch": bench_swatch,
            "swatch_frictionless": lambda: bench_swatch(friction=False),
            "drape_stable_step": bench_drape_stable_step, "body": bench_body, "shell_strip": bench_shell_strip,
            "suite": bench_suite}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    # No ``choices`` with ``nargs="*"``: argparse checks a list default against them as one value.
    parser.add_argument("sections", nargs="*", metavar="section",
                        help=f"sections to run: {', '.join(sorted(SECTIONS))} (default: all)")
    args = parser.parse_args(argv)
    unknown = sorted(set(args.sections) - set(SECTIONS))
    if unknown:
        parser.error(f"unknown section(s) {', '.join(unknown)}; choose from {', '.join(sorted(SECTIONS))}")
    for name in args.sections or sorted(SECTIONS):
        SECTIONS[name]()
    return 0


if __name__ == "__main__":
    sys.exit(main())
