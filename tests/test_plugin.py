"""The yarnfit.shell MuJoCo plugin (compiled by `pip install -e .`), run inside MuJoCo: loading
through plain `import mujoco`, forces against an independent implementation of the same discrete
energy, against MuJoCo's own isotropic membrane, rigid motions, and bad configuration."""

import math

import mujoco
import numpy as np
import pytest

# A fabric-like material (Pa, m): h s00 = 900 N/m, strong anisotropy and coupling.
MATERIAL = {"s00": 3.0e6, "s01": 6.0e5, "s11": 1.5e6, "s22": 2.0e5, "b00": 1.0e6, "b01": 1.0e5, "b11": 8.0e5,
            "b22": 2.0e5, "thickness": 3.0e-4}
# Central differences of a smooth energy at step 1e-7 m on 0.1 m cells: truncation ~1e-10
# relative, round-off ~ε W / (δ |∇W|) ~ 1e-9; 1e-6 is the bound.
GRADIENT_RTOL = 1e-6
# Same formula evaluated by two codes: a few ulps per term, summed over a handful of triangles.
ROUND_OFF_RTOL = 1e-12
FD_STEP = 1e-7  # m
# Force on a vertex of an unstrained sheet (N): round-off of ε ~ 1e-16 times s h × cell ~ 1e2 N is
# ~1e-14; 1e-9 is far below the ~10 N a 1 % strain gives.
UNSTRAINED_FORCE_ATOL = 1e-9


def scene(material=MATERIAL, angle=0.0, count="5 4 1", dim=2, builtin=None, plugin=True) -> str:
    config = "".join(f'<config key="{k}" value="{v!r}"/>' for k, v in material.items())
    if angle:
        config += f'<config key="angle" value="{angle!r}"/>'
    inner = f'<plugin plugin="yarnfit.shell">{config}</plugin>' if plugin else ""
    if builtin:
        inner += builtin
    extension = '<extension><plugin plugin="yarnfit.shell"/></extension>' if plugin else ""
    return (f'<mujoco>{extension}<option gravity="0 0 0"/><worldbody>'
            f'<flexcomp name="cloth" type="grid" count="{count}" spacing="0.1 0.08 0.1" dim="{dim}" radius="0.001" '
            f'mass="0.1">{inner}</flexcomp></worldbody></mujoco>')


def forces(model, qpos):
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_forward(model, data)
    return data.qfrc_passive.copy(), data.flexvert_xpos.copy()


def membrane_energy(model, x, material, angle):
    """The plugin's membrane energy, written independently: Σ A0 (h/2) εᵀ S ε over triangles, rest
    shape at qpos0, weft = world x in the sheet's plane turned by ``angle``."""
    rest = forces(model, model.qpos0)[1]
    tri = model.flex_elem.reshape(-1, 3)
    a, b = rest[tri[0, 1]] - rest[tri[0, 0]], rest[tri[0, 2]] - rest[tri[0, 0]]
    normal = np.cross(a, b) / np.linalg.norm(np.cross(a, b))
    ref = np.array([1.0, 0.0, 0.0])
    axis0 = ref - (ref @ normal) * normal
    axis0 /= np.linalg.norm(axis0)
    axis1 = np.cross(normal, axis0)
    axis0, axis1 = math.cos(angle) * axis0 + math.sin(angle) * axis1, -math.sin(angle) * axis0 + math.cos(angle) * axis1
    S = np.array([[material["s00"], material["s01"], 0], [material["s01"], material["s11"], 0], [0, 0, material["s22"]]])
    total = 0.0
    for t in tri:
        D = np.array([[(rest[t[k]] - rest[t[0]]) @ axis for k in (1, 2)] for axis in (axis0, axis1)])
        F = np.column_stack([x[t[1]] - x[t[0]], x[t[2]] - x[t[0]]]) @ np.linalg.inv(D)
        E = 0.5 * (F.T @ F - np.eye(2))
        eps = np.array([E[0, 0], E[1, 1], 2 * E[0, 1]])
        area = 0.5 * abs(np.linalg.det(D))
        total += area * 0.5 * material["thickness"] * eps @ S @ eps
    return total


@pytest.fixture(scope="module")
def model():
    return mujoco.MjModel.from_xml_string(scene())


def test_plain_import_mujoco_finds_the_plugin(model):
    assert model.nplugin == 1
    assert repr(MATERIAL["s00"]).encode() in model.plugin_attr.tobytes()


@pytest.mark.parametrize("angle", [0.0, 0.4])
def test_forces_are_minus_the_gradient_of_the_energy(angle):
    model = mujoco.MjModel.from_xml_string(scene(angle=angle))
    rng = np.random.default_rng(7)
    qpos = model.qpos0 + 0.01 * rng.standard_normal(model.nq)
    qfrc, x = forces(model, qpos)
    # Every vertex is a body with three world-aligned slide joints: qfrc is the vertex force.
    dof = np.array([model.body_dofadr[b] for b in model.flex_vertbodyid])
    force = np.stack([qfrc[a:a + 3] for a in dof])
    gradient = np.zeros_like(x)
    for v in range(len(x)):
        for i in range(3):
            step = np.zeros_like(x)
            step[v, i] = FD_STEP
            gradient[v, i] = (membrane_energy(model, x + step, MATERIAL, angle)
                              - membrane_energy(model, x - step, MATERIAL, angle)) / (2 * FD_STEP)
    np.testing.assert_allclose(force, -gradient, rtol=0, atol=GRADIENT_RTOL * np.abs(gradient).max())


def test_isotropic_coefficients_give_mujocos_own_membrane():
    E, nu, h = 2.0e6, 0.3, 3.0e-4
    s00 = E / (1 - nu**2)
    isotropic = {**MATERIAL, "s00": s00, "s01": nu * s00, "s11": s00, "s22": E / (2 * (1 + nu)), "thickness": h}
    ours = mujoco.MjModel.from_xml_string(scene(isotropic))
    theirs = mujoco.MjModel.from_xml_string(scene(plugin=False, builtin=(
        f'<elasticity young="{E!r}" poisson="{nu!r}" thickness="{h!r}" elastic2d="stretch"/>')))
    qpos = ours.qpos0 + 0.01 * np.random.default_rng(3).standard_normal(ours.nq)
    a, b = forces(ours, qpos)[0], forces(theirs, qpos)[0]
    np.testing.assert_allclose(a, b, rtol=0, atol=ROUND_OFF_RTOL * np.abs(b).max())


def test_rest_and_rigid_motions_carry_no_force(model):
    qfrc, _ = forces(model, model.qpos0)
    assert np.abs(qfrc).max() < UNSTRAINED_FORCE_ATOL
    rotation = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]) @ np.array(
        [[1.0, 0.0, 0.0], [0.0, math.cos(0.7), -math.sin(0.7)], [0.0, math.sin(0.7), math.cos(0.7)]])
    rest = np.array([model.body_pos[b] for b in model.flex_vertbodyid])
    qpos = (rest @ rotation.T + [0.1, -0.2, 0.3] - rest).ravel()
    qfrc, _ = forces(model, qpos)
    assert np.abs(qfrc).max() < UNSTRAINED_FORCE_ATOL


BAD = {
    "negative": ({**MATERIAL, "s11": -1.0}, "config key 's11' must be positive"),
    "not a number": ({**MATERIAL, "b22": "soft"}, "config key 'b22' must be a finite number"),
    "infinite": ({**MATERIAL, "thickness": "inf"}, "config key 'thickness' must be a finite number"),
    "indefinite S": ({**MATERIAL, "s01": 3.0e6}, "membrane matrix S is not positive definite"),
    "indefinite B": ({**MATERIAL, "b01": -1.0e6}, "bending matrix B is not positive definite"),
    "missing key": ({k: v for k, v in MATERIAL.items() if k != "s22"}, "config key 's22' is required"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_configuration_fails_compilation_naming_the_problem(case):
    material, message = BAD[case]
    with pytest.raises(ValueError, match=message):
        mujoco.MjModel.from_xml_string(scene(material))


def test_a_plugin_on_a_1d_flex_fails_compilation():
    with pytest.raises(ValueError, match="needs a 2D flex"):
        mujoco.MjModel.from_xml_string(scene(count="6 1 1", dim=1))
