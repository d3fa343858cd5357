"""Full-body scene (yarnfit.validate.body) at quick scale: the humanoid and the one-flex garments
sewn from their panels build and compile with the pattern's rest, the scripted motion runs without
instability, the garments stay on the body and crease, and the recording reads back with the
documented entity paths."""

import functools
import re

import mujoco
import numpy as np
import pytest
import rerun as rr
import trimesh

import yarnfit.validate.body as body
from fabric_shell import FABRIC
from yarnfit.mujoco.scenes import ClothMaterial
from yarnfit.validate.body import (DISTANCE_TARGET, PENETRATION_TARGET, build_body_scene, compile_body_scene,
                                   garment_pattern, motion_targets, run_body, sewn_garment)

AREAL_DENSITY = 0.2  # kg/m²: a medium-weight woven
# The targets hold at quick scale too (5 cm panels, 2 s). Measured: this woven, farthest
# garment vertex 0.129 m from the capsules, deepest 2.7 mm; the fitted polyester jersey / cotton
# twill pair 0.114 m and 3.6 mm.
QUICK_DISTANCE_LIMIT = DISTANCE_TARGET


def material():
    return ClothMaterial("test-woven", FABRIC, AREAL_DENSITY)


@functools.lru_cache(maxsize=None)
def quick_run(path):
    return run_body(material(), quick=True, recording_path=path).summary()


def test_garments_are_sewn_into_consistent_manifolds():
    for kind in ("shirt", "pants"):
        points, triangles, seam = garment_pattern(kind, body.QUICK_SPACING)
        assert 0 < seam.sum() < len(seam)
        garment = sewn_garment(kind, body.QUICK_SPACING)
        assert len(garment.points) == 2 * len(points) - seam.sum()  # each seam vertex kept once
        mesh = trimesh.Trimesh(garment.points, garment.triangles, process=False)
        assert mesh.is_winding_consistent  # the back panel turned over: one orientation across the seams
        assert np.isclose(garment.rest_areas().sum(), 2 * trimesh.Trimesh(
            np.column_stack([points, np.zeros(len(points))]), triangles, process=False).area)
    with pytest.raises(ValueError, match="unknown garment 'hat'"):
        garment_pattern("hat", body.QUICK_SPACING)


def test_scene_compiles_with_the_patterns_rest_and_motion_is_smooth():
    spec, garments = build_body_scene(material(), material(), spacing=body.QUICK_SPACING)
    model = compile_body_scene(spec, garments)
    assert model.nflex == 2 and all(mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_FLEX, n) >= 0 for n in ("shirt", "pants"))
    assert model.nu == 10
    assert all(model.equality(i).name.startswith("pants_belt_") for i in range(model.neq))  # no seam equalities
    for kind, g in garments.items():
        f = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_FLEX, kind)
        edges = model.flex_edge[model.flex_edgeadr[f]:model.flex_edgeadr[f] + model.flex_edgenum[f]]
        start = np.linalg.norm(np.diff(g["garment"].points[edges], axis=1)[:, 0], axis=1)
        rest = model.flexedge_length0[model.flex_edgeadr[f]:model.flex_edgeadr[f] + model.flex_edgenum[f]]
        assert rest.max() <= body.QUICK_SPACING * (1 + 1e-6)  # the pattern's cells, not the flat panels' seam gap
        assert start.max() > 2 * rest.max()
    # Garment–body contacts at the body's time constant: MuJoCo mixes a contact's solref from both
    # sides, so the flexes carry the capsules' own.
    capsules = model.geom_solref[model.geom_type == mujoco.mjtGeom.mjGEOM_CAPSULE]
    assert len(capsules) and np.all(capsules == capsules[0])
    np.testing.assert_array_equal(model.flex_solref, np.tile(capsules[0], (model.nflex, 1)))
    assert motion_targets(0.0) == {} or all(v == 0 for v in motion_targets(0.0).values())
    # Keyframes are reached exactly, and the script is continuous.
    assert abs(motion_targets(2.0)["l_shoulder"] + np.radians(60)) < 1e-12
    samples = [motion_targets(t).get("l_shoulder", 0.0) for t in np.arange(0, 8, 1e-3)]
    assert np.max(np.abs(np.diff(samples))) < 1e-2


def test_quick_run_is_stable_and_garments_stay_on(tmp_path_factory):
    path = str(tmp_path_factory.getbasetemp() / "body.rrd")
    result = quick_run(path)
    assert result["stable"], result
    assert result["bad_qacc"] == 0 and not result["nonfinite"]
    assert result["simulated_s"] == body.QUICK_SECONDS
    assert result["max_penetration_m"] < PENETRATION_TARGET
    assert result["max_distance_m"] < QUICK_DISTANCE_LIMIT
    assert result["ms_per_step"] > 0
    assert all(c["hinges"] > 0 for c in result["creases"].values())
    assert all(s["max_stretch"] < 0.2 for s in result["sewing"].values())  # sewn on: a few per cent left

    # The recording: every documented path and the sim_time timeline.
    documented = set(re.findall(r"``(body(?:/[\w<>]+)*)``", body.__doc__))
    capsules = {f"body/bodies/{name}" for name in ("pelvis", "torso", "head", "l_upper_arm", "r_upper_arm",
                                                   "l_lower_arm", "r_lower_arm", "l_thigh", "r_thigh",
                                                   "l_shin", "r_shin")}
    expected = (documented - {"body/bodies/<geom"}) | capsules
    expected = {p for p in expected if "<" not in p}
    seen, timelines = set(), set()
    frames = {}
    for chunk in rr.chunk.RrdReader(path).stream():
        entity = chunk.entity_path.lstrip("/")
        seen.add(entity)
        timelines |= set(chunk.timeline_names)
        if entity == "body/cloth/shirt":
            batch = chunk.to_record_batch()
            column = [n for n in batch.schema.names if "vertex_positions" in n.lower()]
            for name in column:
                frames.setdefault("shirt", []).extend(v for v in batch.column(name).to_pylist() if v)
    assert expected <= seen, expected - seen
    assert "sim_time" in timelines
    assert len(frames["shirt"]) > 10  # one per 1/30 s of the 2 s run
    last = np.asarray(frames["shirt"][-1], float)
    assert last.shape == (result["garments"]["shirt"]["vertices"], 3) and np.all(np.isfinite(last))


def test_humanoid_is_human_sized():
    model = mujoco.MjModel.from_xml_path(str(body.HUMANOID))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    top = max(data.geom_xpos[g, 2] + model.geom_size[g, 0] + model.geom_size[g, 1] for g in range(model.ngeom)
              if model.geom(g).name == "head")
    assert 1.70 < top < 1.80  # about 1.75 m tall
    assert 50 < model.body_subtreemass[0] < 100


def test_an_unknown_solver_is_refused():
    material = ClothMaterial("woven", FABRIC, 0.2)
    with pytest.raises(ValueError, match="unknown solver 'pgs'; solvers: newton, cg"):
        build_body_scene(material, material, solver="pgs")
