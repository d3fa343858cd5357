"""The drapes (yarnfit.validate.drape) and the `yarnfit validate` suite: summaries, recordings,
bad input."""

import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import rerun as rr
import trimesh

import yarnfit
from fabric_shell import FABRIC
from yarnfit.mujoco.scenes import ClothMaterial
from yarnfit.validate.drape import RESOLUTION, SIZE, fold_count, projected_area, run_drape

DENSITY = 0.2  # kg/m²
WOVEN = ClothMaterial("woven", FABRIC, DENSITY)
# The raster of projected_area resolves a square to a cell row along each edge: 1/400 per side.
AREA_RTOL = 0.01


def material_file(folder: Path, shell=FABRIC, name="woven", version=yarnfit.__version__) -> Path:
    path = folder / f"{name}.json"
    path.write_text(json.dumps({"yarnfit_version": version,
                                "inputs": {"fabric": name, "areal_density_kg_m2": DENSITY},
                                "shell": shell.to_dict(), "engineering": shell.engineering()}))
    return path


def test_projected_area_of_flat_and_folded_squares():
    x, y = np.meshgrid(np.linspace(0, 1, 11), np.linspace(0, 1, 11), indexing="ij")
    points = np.column_stack([x.ravel(), y.ravel(), np.zeros(121)])
    a = (np.arange(10)[:, None] * 11 + np.arange(10)[None, :]).ravel()
    triangles = np.concatenate([np.stack([a, a + 11, a + 12], 1), np.stack([a, a + 12, a + 1], 1)])
    assert projected_area(points, triangles) == pytest.approx(1.0, rel=AREA_RTOL)
    folded = points.copy()
    over = folded[:, 0] > 0.5
    folded[over, 0] = 1.0 - folded[over, 0]  # folded in half along x = 0.5
    folded[over, 2] = 0.01
    assert projected_area(folded, triangles) == pytest.approx(0.5, rel=AREA_RTOL)


def test_fold_count_counts_the_lobes_of_a_hem():
    angle = np.linspace(0, 2 * np.pi, 720, endpoint=False)
    radius = 0.15 + 0.02 * np.cos(6 * angle)
    hem = np.column_stack([radius * np.cos(angle), radius * np.sin(angle), np.zeros_like(angle)])
    assert fold_count(hem, np.arange(len(hem)), SIZE) == 6


def entity_paths(path):
    return {chunk.entity_path for chunk in rr.chunk.RrdReader(path).stream()}


@pytest.mark.parametrize("scene", ["sphere", "wall"])
def test_drape_settles_and_records(scene, tmp_path):
    path = tmp_path / f"{scene}.rrd"
    summary = run_drape(WOVEN, scene, quick=True, recording_path=path).summary()
    assert summary["settled"] and summary["bad_qacc"] == 0
    assert 0 < summary["drape_coefficient"] < 1
    assert summary["lowest_point_m"] > -0.005  # the floor (less the flex radius)
    paths = entity_paths(path)
    assert {f"/{scene}/cloth", f"/{scene}/bodies/obstacle", f"/{scene}/plots/kinetic_energy",
            f"/{scene}/plots/lowest_point", f"/{scene}/summary"} <= paths
    final = trimesh.load(summary["final_mesh"], process=False)
    n = RESOLUTION[True]
    # criss-cross cells: the grid vertices and one centre per cell
    assert final.vertices.shape == (n * n + (n - 1) ** 2, 3) and final.vertices[:, 2].min() == pytest.approx(
        summary["lowest_point_m"], abs=1e-6)
    if scene == "sphere":
        assert summary["fold_count"] >= 2
    else:
        assert 0 < summary["max_distance_from_wall_m"] < SIZE


def test_stiffer_fabrics_drape_differently_on_the_sphere():
    """The paper's check (c), in kind: the same construction, a fibre 5× stiffer in bending,
    stands out further (a larger drape coefficient)."""
    stiff = dataclasses.replace(FABRIC, b00=5 * FABRIC.b00, b01=5 * FABRIC.b01, b11=5 * FABRIC.b11,
                                b22=5 * FABRIC.b22)
    soft = run_drape(WOVEN, "sphere", quick=True).drape_coefficient
    hard = run_drape(ClothMaterial("stiff", stiff, DENSITY), "sphere", quick=True).drape_coefficient
    assert hard > soft + 0.02


def yarnfit_cli(*args):
    script = Path(sys.executable).with_name("yarnfit")
    return subprocess.run([str(script), *args], capture_output=True, text=True, timeout=300)


def test_cli_validate_writes_recordings_and_a_summary(tmp_path):
    material = material_file(tmp_path)
    logs = tmp_path / "logs"
    done = yarnfit_cli("validate", str(material), "--scenes", "stretch,sphere,wall", "--quick", "--logs", str(logs))
    assert done.returncode == 0, done.stderr
    folder = logs / "woven"
    summary = json.loads((folder / "summary.json").read_text())
    assert set(summary["scenes"]) == {"stretch", "sphere", "wall"} and summary["quick"] is True
    for scene in summary["scenes"]:
        assert (folder / f"{scene}.rrd").is_file()
        assert summary["wall_seconds"][scene] > 0
    assert summary["bias_softness"]["8x5"]["bias_softer"]  # the paper's check (a) on the test woven
    assert "stretch: done" in done.stderr  # progress
    checks = {v["check"]: v for v in summary["verdicts"]}  # one line each, printed and kept
    assert checks["sphere drape settled"]["passed"] and checks["wall drape settled"]["passed"]
    assert "pass  sphere drape settled" in done.stdout


@pytest.mark.parametrize("case", ["missing keys", "old version", "reference without units", "unknown scene"])
def test_cli_validate_bad_input_is_one_line(case, tmp_path):
    material = material_file(tmp_path)
    args = [str(material), "--scenes", "stretch", "--quick", "--logs", str(tmp_path / "logs")]
    if case == "missing keys":
        material.write_text(json.dumps({"yarnfit_version": yarnfit.__version__, "shell": FABRIC.to_dict()}))
        message = "missing keys inputs, engineering"
    elif case == "old version":
        material_file(tmp_path, version="0.0.3")
        message = "written by yarnfit '0.0.3'"
    elif case == "reference without units":
        csv = tmp_path / "ref.csv"
        csv.write_text("direction,strain,force per width\nweft,0.01,10\n")
        args += ["--reference", str(csv)]
        message = "column 'strain' has no unit"
    else:
        args[2] = "stretch,drape"
        message = "unknown scene drape"
    done = yarnfit_cli("validate", *args)
    assert done.returncode == 2
    assert message in done.stderr and len(done.stderr.strip().splitlines()) == 1


def test_shell_and_yarn_curves_are_compared_at_the_yarn_strains():
    from yarnfit.validate.suite import compare_shell_yarn

    stretch = {"strips": {"8x5_weft": {"strain": [0.01, 0.05, 0.1], "force_per_width_n_per_m": [10.0, 50.0, 100.0],
                                       "compression_ratio": [1.0, 0.98, 0.96]}}}
    yarn = {"directions": {"weft": {"strain": [0.02, 0.05, 0.2], "force_n_per_m": [25.0, 40.0, 1.0],
                                    "compression_ratio": [0.99, 0.97, 0.9]},
                           "warp": {"strain": [0.02], "force_n_per_m": [1.0], "compression_ratio": [1.0]}}}
    result = compare_shell_yarn(stretch, yarn)
    assert set(result) == {"weft"}  # no shell warp strip
    weft = result["weft"]
    assert weft["strain"] == [0.02, 0.05]  # 20 % lies beyond the shell's pull
    np.testing.assert_allclose(weft["shell_force_n_per_m"], [20.0, 50.0])
    np.testing.assert_allclose(weft["force_relative_difference"], [20 / 25 - 1, 50 / 40 - 1])
    np.testing.assert_allclose(weft["shell_compression_ratio"], [0.995, 0.98])


def test_a_yarn_point_just_past_the_shells_measured_strain_is_compared_by_extension():
    from yarnfit.validate.suite import compare_shell_yarn

    stretch = {"strips": {"8x5_warp": {"strain": [0.0495, 0.099], "force_per_width_n_per_m": [50.0, 100.0],
                                       "compression_ratio": [0.99, 0.98]}}}
    yarn = {"directions": {"warp": {"strain": [0.05, 0.1], "force_n_per_m": [50.0, 100.0],
                                    "compression_ratio": [0.99, 0.98]}}}
    warp = compare_shell_yarn(stretch, yarn)["warp"]
    assert warp["strain"] == [0.05, 0.1]
    np.testing.assert_allclose(warp["shell_force_n_per_m"], [50.0 + 0.0005 / 0.0495 * 50, 100.0 + 0.001 / 0.0495 * 50])


def _figures(summary: dict) -> dict:
    """A scene summary without what differs between two identical runs: timings and file paths."""
    return {key: value for key, value in summary.items()
            if not any(word in key for word in ("seconds", "ms_per_step", "mesh", "path"))}


def test_scenes_run_side_by_side_give_the_same_figures(tmp_path):
    """Two workers (the command line's default on 2 cores) and one scene after another in this
    process: the same figures, bit for bit (each scene is deterministic and runs alone in its
    process), every scene's recording written and its progress forwarded, and an unknown scene
    refused."""
    from yarnfit.tasks import LocalPool
    from yarnfit.validate.suite import run_suite

    material = material_file(tmp_path)
    scenes = ("cusick", "sphere")
    alone, _ = run_suite(material, scenes, quick=True, logs=tmp_path / "alone")
    lines = []
    with LocalPool(2) as backend:
        side, path = run_suite(material, scenes, quick=True, logs=tmp_path / "side", backend=backend,
                               progress=lines.append)
    # The workers' own progress reaches the caller, each line naming its scene.
    assert any(line.startswith("cusick drape:") for line in lines)
    assert any(line.startswith("sphere drape:") for line in lines)
    for scene in scenes:
        assert _figures(side["scenes"][scene]) == _figures(alone["scenes"][scene])
        assert (path.parent / f"{scene}.rrd").is_file() and side["wall_seconds"][scene] > 0
    assert [v["passed"] for v in side["verdicts"]] == [v["passed"] for v in alone["verdicts"]]
    with pytest.raises(ValueError, match="unknown scene 'drape'"):
        run_suite(material, ("cusick", "drape"), quick=True, logs=tmp_path / "bad")


def test_ctrl_c_stops_scenes_running_side_by_side(tmp_path):
    """Ctrl-C in a terminal (SIGINT to the whole process group) while two scenes run on worker
    processes: exit 130 within STOP_SECONDS with one line and no traceback, no process of the run
    left (workers, the progress queue's manager), no summary and no part-written recording."""
    import os
    import signal
    import time

    from test_tasks import STOP_SECONDS, checkout_env, default_sigint

    material = material_file(tmp_path)
    logs = tmp_path / "logs"
    command = [sys.executable, "-m", "yarnfit.cli", "validate", str(material), "--scenes", "sphere,wall",
               "--logs", str(logs), "--workers", "2"]
    run = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                           env=checkout_env(), preexec_fn=default_sigint, start_new_session=True)
    for line in run.stderr:  # the first line a worker forwards: both scenes are running
        if "drape:" in line:
            break
    else:
        pytest.fail("the suite ended before its scenes reported")
    helpers = subprocess.run(["pgrep", "-P", str(run.pid)], capture_output=True, text=True).stdout.split()
    assert len(helpers) >= 3  # two workers and the manager
    start = time.perf_counter()
    os.killpg(run.pid, signal.SIGINT)
    rest = run.stderr.read()
    assert run.wait(timeout=10) == 130
    assert time.perf_counter() - start < STOP_SECONDS
    lines = [line for line in rest.splitlines() if line.strip() and "drape:" not in line]  # forwarded lines may trail
    assert lines == ["yarnfit validate: interrupted"] and "Traceback" not in rest, rest
    time.sleep(0.2)
    assert [pid for pid in helpers if os.path.exists(f"/proc/{pid}")] == []
    assert list((logs / "woven").iterdir()) == []
