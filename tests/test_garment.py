"""One-flex garments (issue 15 item 3): the plugin's rest from texture coordinates
(``rest="texcoord"``), its exact removal of MuJoCo's built-in elasticity whatever that part's rest,
use_pattern_rest against MuJoCo's own compiler, and sewing panels into one mesh."""

import math

import mujoco
import numpy as np
import pytest

from test_plugin import (GRADIENT_RTOL, MATERIAL, ROUND_OFF_RTOL, ReferenceShell, central_gradient, compile_sheet, forces,
                         mesh_spec, vertex_forces)
from yarnfit.mujoco.garment import Panel, Seam, sew, use_pattern_rest
from yarnfit.mujoco.scenes import grid_mesh, panel_mesh

# Built-in elasticity of the tests (Pa, -, m, s): stiffer than the material's membrane and
# bending, as the split's is, with its own damping time, which the plugin must remove too.
BUILTIN = {"young": 4.0e6, "poisson": 0.3, "thickness": 4.0e-4, "damping": 0.02}
ROLL_RADIUS = 0.08  # m: the qpos0 shape of a panel rolled about the y axis, far from its flat rest


def rolled(flat: np.ndarray) -> np.ndarray:
    """``flat (V, 2)`` pattern points wrapped isometrically onto a cylinder of radius ROLL_RADIUS."""
    u, v = flat[:, 0], flat[:, 1]
    return np.column_stack([ROLL_RADIUS * np.sin(u / ROLL_RADIUS), v, ROLL_RADIUS * (1 - np.cos(u / ROLL_RADIUS))])


def garment_model(points, triangles, corner_uv=None, material=MATERIAL, elastic2d=None, damping=0.0,
                  builtin=BUILTIN):
    """A free sheet (``points (V, 3)`` at qpos0, ``triangles (T, 3)``), one body with three slide
    joints per vertex, the plugin with the whole material; with ``corner_uv (T, 3, 2)`` its rest is
    those texture coordinates (``rest="texcoord"``); with ``elastic2d`` MuJoCo's built-in
    elasticity ``builtin`` (:data:`BUILTIN`) too."""
    config = {key: value if isinstance(value, str) else repr(value) for key, value in material.items()}
    if damping:
        config["damping"] = repr(damping)
    if corner_uv is not None:
        config["rest"] = "texcoord"
    spec, flex = mesh_spec(points, triangles, config)
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_DISCRETE
    if corner_uv is not None:
        flex.texcoord = np.asarray(corner_uv, np.float32).ravel()
        flex.elemtexcoord = np.arange(3 * len(triangles))
    if elastic2d:
        flex.young, flex.poisson, flex.thickness = builtin["young"], builtin["poisson"], builtin["thickness"]
        flex.damping = builtin["damping"]
        flex.elastic2d = {"stretch": 2, "both": 3, "bend": 1}[elastic2d]
    return compile_sheet(spec)


def panel():
    """An unstructured pentagonal panel (V, 2) and its triangles, pattern coordinates in float32."""
    outline = np.array([[0.0, 0.0], [0.3, 0.0], [0.3, 0.2], [0.1, 0.25], [0.0, 0.2]])
    points, triangles = panel_mesh(outline, 0.04, seed=1)
    return points[:, :2].astype(np.float32).astype(float), triangles


def set_state(model, x, v=None):
    data = mujoco.MjData(model)
    for k, b in enumerate(model.flex_vertbodyid):
        data.qpos[model.jnt_qposadr[model.body_jntadr[b]]:][:3] = x[k] - model.body_pos[b]
        if v is not None:
            data.qvel[model.body_dofadr[b]:][:3] = v[k]
    mujoco.mj_forward(model, data)
    return data


@pytest.mark.parametrize("poisson", [0.1, 0.3])
def test_use_pattern_rest_gives_what_mujoco_compiles_for_the_flat_pattern(poisson):
    """Rewritten from the texture coordinates of a rolled panel, MuJoCo's rest edge lengths,
    membrane metric and hinge operators equal what its own compiler computes for the same panel
    laid flat (an unstructured mesh: every cotangent different)."""
    flat, triangles = panel()
    builtin = {**BUILTIN, "poisson": poisson}
    reference = garment_model(np.column_stack([flat, np.zeros(len(flat))]), triangles, flat[triangles],
                              elastic2d="both", builtin=builtin)
    model = garment_model(rolled(flat), triangles, flat[triangles], elastic2d="both", builtin=builtin)
    assert np.abs(model.flex_bending.reshape(-1, 17)[:, 16]).max() > 0  # the rolled rest is curved
    use_pattern_rest(model, "sheet", builtin["young"], builtin["poisson"], builtin["thickness"])
    for name in ("flexedge_length0", "flex_stiffness", "flex_bending"):
        expected, got = getattr(reference, name), getattr(model, name)
        np.testing.assert_allclose(got, expected, rtol=0, atol=ROUND_OFF_RTOL * np.abs(expected).max(), err_msg=name)


@pytest.mark.parametrize("patched", [False, True])
@pytest.mark.parametrize("elastic2d", ["stretch", "both"])
def test_texcoord_rest_on_a_rolled_panel_is_the_flat_panel(elastic2d, patched):
    """A panel whose qpos0 is rolled onto a cylinder, its rest given by texture coordinates, pulls
    exactly as the same panel compiled flat (rest from qpos0) at the same positions: the rest
    metric and material axes come from the pattern. MuJoCo's built-in elasticity on it, whatever
    its rest (its qpos0 curvature, or the pattern's after use_pattern_rest) is removed exactly,
    damping included: the total is the configured material's alone."""
    flat, triangles = panel()
    angle = 0.4
    material = {**MATERIAL, "angle": angle}
    alone = garment_model(np.column_stack([flat, np.zeros(len(flat))]), triangles, material=material, damping=0.01)
    model = garment_model(rolled(flat), triangles, flat[triangles], material=material, elastic2d=elastic2d,
                          damping=0.01)
    if patched:
        use_pattern_rest(model, "sheet", BUILTIN["young"], BUILTIN["poisson"], BUILTIN["thickness"])
    rng = np.random.default_rng(4)
    x = np.column_stack([flat, 0.05 * np.sin(6 * flat[:, 0])]) + 0.003 * rng.standard_normal((len(flat), 3))
    v = 0.1 * rng.standard_normal((len(flat), 3))
    a, b = set_state(alone, x, v), set_state(model, x, v)
    assert np.abs(b.qfrc_spring).max() > 1e-3 * np.abs(b.qfrc_passive).max()  # MuJoCo's part is really there
    np.testing.assert_allclose(b.qfrc_passive, a.qfrc_passive, rtol=0,
                               atol=ROUND_OFF_RTOL * np.abs(a.qfrc_passive).max())


def pillowcase(grain_back=0.4):
    """Two 0.2 × 0.15 m criss-cross panels sewn along both long sides into a tube: the back one
    turned over (its triangles reversed) and cut with its weft at ``grain_back`` rad."""
    points, triangles = grid_mesh(5, 4, 0.2, 0.15, crisscross=True)
    flat = points[:, :2]
    side = np.abs(np.abs(flat[:, 0]) - 0.1) < 1e-12
    left = np.flatnonzero(side & (flat[:, 0] < 0))
    right = np.flatnonzero(side & (flat[:, 0] > 0))
    front = Panel("front", flat, triangles, np.column_stack([flat, np.full(len(flat), 0.02)]))
    back = Panel("back", flat, triangles[:, ::-1], np.column_stack([flat, np.full(len(flat), -0.02)]), grain_back)
    return sew([front, back], [Seam("front", left, "back", left), Seam("front", right, "back", right)])


def test_sewing_merges_the_seams_and_keeps_each_panels_pattern():
    garment = pillowcase()
    assert len(garment.points) == 2 * 32 - 8  # 4 vertices on each of the two seams kept once
    assert len(garment.seam_vertices) == 8
    assert np.allclose(garment.points[garment.seam_vertices, 2], 0.0)  # between the panels' placements
    assert np.isclose(garment.rest_areas().sum(), 2 * 0.2 * 0.15)
    # The back panel's corners are its pattern turned by its grain: lengths kept, axes turned.
    back = garment.panel_of_triangle == 1
    e_front = garment.corner_uv[~back][:, 1] - garment.corner_uv[~back][:, 0]
    e_back = garment.corner_uv[back][:, 1] - garment.corner_uv[back][:, 2]  # reversed: (c, b, a)
    np.testing.assert_allclose(np.linalg.norm(e_back, axis=1), np.linalg.norm(e_front, axis=1))
    angle = math.atan2(e_back[0, 1], e_back[0, 0]) - math.atan2(e_front[0, 1], e_front[0, 0])
    assert math.isclose(math.remainder(angle, 2 * math.pi), -0.4)


def test_sewing_rejects_seams_of_unequal_length():
    points, triangles = grid_mesh(3, 3, 0.1, 0.1)
    flat = points[:, :2]
    a = Panel("a", flat, triangles, points)
    b = Panel("b", flat * [1.0, 1.1], triangles, points)
    side = np.flatnonzero(np.isclose(flat[:, 0], -0.05))
    with pytest.raises(ValueError, match="differ in length"):
        sew([a, b], [Seam("a", side, "b", side)])
    with pytest.raises(ValueError, match="unknown panel"):
        sew([a, b], [Seam("a", side, "c", side)])


def test_a_sewn_tube_of_two_grains_is_minus_the_gradient_of_its_pattern_energy():
    """Two panels of different grain sewn into a tube, started from their flat placements and
    deformed: the plugin (with MuJoCo's built-in part on it, removed) pulls with minus the gradient
    of the reference energy over each triangle's own pattern corners, the hinges across the seams
    bending with the far triangle's rest distances from the edge."""
    garment = pillowcase()
    model = garment_model(garment.points, garment.triangles, garment.corner_uv, elastic2d="both")
    use_pattern_rest(model, "sheet", BUILTIN["young"], BUILTIN["poisson"], BUILTIN["thickness"])
    reference = ReferenceShell(model, MATERIAL, corner_uv=model.flex_texcoord.astype(float).reshape(-1, 3, 2))
    assert len(reference.hinges) > 0
    x = garment.points + 0.004 * np.random.default_rng(8).standard_normal(garment.points.shape)
    qfrc, _ = forces(model, (x - np.array([model.body_pos[b] for b in model.flex_vertbodyid])).ravel())
    gradient = central_gradient(reference.energy, x)
    np.testing.assert_allclose(vertex_forces(model, qfrc), -gradient, rtol=0,
                               atol=GRADIENT_RTOL * np.abs(gradient).max())


def test_texcoord_rest_needs_texture_coordinates_and_no_builtin_keys():
    flat, triangles = panel()
    points = np.column_stack([flat, np.zeros(len(flat))])
    spec_error = "has no texture coordinates"
    with pytest.raises(ValueError, match=spec_error):
        garment_model(points, triangles, material={**MATERIAL, "rest": "texcoord"})
    with pytest.raises(ValueError, match="'builtin_"):
        garment_model(points, triangles, flat[triangles], material={**MATERIAL, "builtin_young": 1e5,
                                                                    "builtin_thickness": 1e-4})
    with pytest.raises(ValueError, match="'rest' must be 'qpos0' or 'texcoord'"):
        garment_model(points, triangles, material={**MATERIAL, "rest": "pattern"})
@pytest.mark.parametrize("mesh", ["panel", "tube"])
def test_node_smoothed_membrane_is_minus_the_gradient_of_its_energy(mesh):
    """membrane="node": strains smoothed over each vertex's third of its triangles, one domain per
    vertex and panel (on the tube the seam vertices have one in each panel, however alike the
    panels' texture coordinates): the forces, with MuJoCo's built-in part removed, are minus the
    gradient of the reference energy over those domains."""
    material = {**MATERIAL, "membrane": "node"}
    if mesh == "panel":
        flat, triangles = panel()
        points = np.column_stack([flat, np.zeros(len(flat))])
        model = garment_model(points, triangles, material=material, elastic2d="both")
        domains = triangles
        reference = ReferenceShell(model, MATERIAL, domains=domains)
    else:
        garment = pillowcase()
        points = garment.points
        model = garment_model(points, garment.triangles, garment.corner_uv, material=material, elastic2d="both")
        use_pattern_rest(model, "sheet", BUILTIN["young"], BUILTIN["poisson"], BUILTIN["thickness"])
        keys = {}
        domains = np.array([[keys.setdefault((int(v), int(p)), len(keys)) for v in tri]
                            for tri, p in zip(garment.triangles, garment.panel_of_triangle)])
        reference = ReferenceShell(model, MATERIAL, corner_uv=model.flex_texcoord.astype(float).reshape(-1, 3, 2),
                                   domains=domains)
    x = points + 0.004 * np.random.default_rng(9).standard_normal(points.shape)
    qfrc, _ = forces(model, (x - np.array([model.body_pos[b] for b in model.flex_vertbodyid])).ravel())
    gradient = central_gradient(reference.energy, x)
    np.testing.assert_allclose(vertex_forces(model, qfrc), -gradient, rtol=0,
                               atol=GRADIENT_RTOL * np.abs(gradient).max())
    per_triangle = ReferenceShell(model, MATERIAL, corner_uv=reference.corner if mesh == "tube" else None)
    assert np.abs(central_gradient(per_triangle.energy, x) - gradient).max() > 1e-3 * np.abs(gradient).max()
