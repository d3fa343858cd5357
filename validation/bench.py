"""Benchmarks of yarnfit, one section per stage.

    python validation/bench.py [engine] [relax] [fit] [mujoco]

prints one ``name: value unit`` line per figure. Numba kernels are compiled (or loaded from the
on-disk cache) before anything is timed.
"""

from __future__ import annotations

import argparse
import math
import sys
import time

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
    """Full shell fits (default sample design, every core) of the five presets and of the HYLC
    stockinette: wall time by stage, the slowest sample, the engineering constants and R² per
    sample family. A small fit runs first, untimed, so that every kernel is compiled."""
    import warnings
    from pathlib import Path

    from yarnfit.fabric import PRESETS, Fabric
    from yarnfit.fabric_fit import fit_fabric
    from yarnfit.fibers import get_fiber

    stockinette = Path(__file__).parents[1] / "tests" / "data" / "hylc" / "stockinette.pyp"
    fabrics = [Fabric.preset(name) for name in PRESETS]
    fabrics.append(Fabric(name="stockinette", fiber=get_fiber("polyester"), pattern_file=stockinette))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit_fabric(fabrics[0], samples=15, workers=1)
        for fabric in fabrics:
            fitted = fit_fabric(fabric)
            key = "fit_" + fabric.name.replace("-", "_")
            seconds = fitted.seconds
            report(f"{key}_seconds", sum(seconds.values()), "s")
            for stage in ("relax", "homogenize", "fit"):
                report(f"{key}_{stage}_seconds", seconds[stage], "s")
            report(f"{key}_slowest_sample_seconds", max(r.seconds for r in fitted.samples), "s (one core)")
            report(f"{key}_samples_fitted", len(fitted.fit.used), f"of {len(fitted.samples)}")
            for name, value in fitted.material.engineering().items():
                report(f"{key}_{name}", value, "")
            for family, quality in fitted.fit.families.items():
                if quality["samples"]:
                    report(f"{key}_r2_{family}", quality["r2"], "")


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


def bench_mujoco() -> None:
    """A 40×40 cloth as ``yarnfit export --scene cloth`` and ``--scene sphere`` write it (their
    integrator and Δt), with the plugin and without it (the same scene, plugin removed), and the
    plugin's own compute at the same states: mj_passive with the plugin minus without it."""
    from pathlib import Path

    import mujoco

    from yarnfit.mujoco.scenes import ClothMaterial, build_scene

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from fabric_shell import FABRIC  # a realistic medium-weight woven

    material = ClothMaterial("medium woven", FABRIC, 0.2)
    for scene in ("cloth", "sphere"):
        built = build_scene(material, scene, resolution=40)
        models = {"with": built.spec.compile(), "without": _without_plugin(built.spec).compile()}
        steps = round(MUJOCO_BENCH_SECONDS / models["with"].opt.timestep)
        ms_per_step, states = {}, []
        for variant, model in models.items():
            data = mujoco.MjData(model)
            mujoco.mj_step(model, data, nstep=10)
            start = time.perf_counter()
            for step in range(steps):
                mujoco.mj_step(model, data)
                if variant == "with" and step % (steps // 10) == 0:
                    states.append((data.qpos.copy(), data.qvel.copy()))
            ms_per_step[variant] = 1e3 * (time.perf_counter() - start) / steps
            if data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number:
                print(f"warning: {scene} {variant} the plugin became unstable", file=sys.stderr)
        passive_ms = {}
        for variant, model in models.items():
            data = mujoco.MjData(model)
            total = 0.0
            for qpos, qvel in states:
                data.qpos[:], data.qvel[:] = qpos, qvel
                mujoco.mj_forward(model, data)
                start = time.perf_counter()
                for _ in range(20):
                    mujoco.mj_passive(model, data)
                total += (time.perf_counter() - start) / 20
            passive_ms[variant] = 1e3 * total / len(states)
        plugin_ms = passive_ms["with"] - passive_ms["without"]
        key = f"mujoco_{scene}_40x40"
        integrator = mujoco.mjtIntegrator(models["with"].opt.integrator).name.removeprefix("mjINT_").lower()
        info = f"{models['with'].opt.timestep:g} s step, {integrator}"
        report(f"{key}_ms_per_step_with_plugin", ms_per_step["with"], f"ms ({info})")
        report(f"{key}_ms_per_step_without_plugin", ms_per_step["without"], "ms")
        report(f"{key}_plugin_compute_ms", plugin_ms, "ms per step")
        report(f"{key}_plugin_compute_fraction", plugin_ms / ms_per_step["without"], "of the step without it")


SECTIONS = {"engine": bench_engine, "relax": bench_relax, "fit": bench_fit, "mujoco": bench_mujoco}


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
