"""The yarnfit.shell plugin's strain-stiffening membrane (config keys ``s00p2`` … ``s22n3``, ``c01``,
``c10``) and compression terms (``s00c s11c s22c``), run inside MuJoCo: forces, with constant-strain
triangles and node-smoothed strains, against an independent numpy implementation of the energy

    W_m = h [½ εᵀ S ε + Σ_d φ_d(y_d) + Σ_d ½ q_d min(ε_d, 0)²],   y = D ε,   φ_d(x) = k2 x³/3 + k3 x⁴/4,

((k2, k3) = (s<dd>p2, s<dd>p3) for x ≥ 0, (s<dd>n2, s<dd>n3) for x < 0; q_d = s<dd>c), its damping
(the tangent's Rayleigh form), rigid motions, uniform patches against the closed-form stress
``σ = h [S ε + Dᵀ φ'(y) + q min(ε, 0)]``, bad keys, and all keys 0 giving the StVK plugin as it
was."""

import json
import math
from pathlib import Path

import mujoco
import numpy as np
import pytest
from scipy.optimize import brentq, least_squares

from test_plugin import MATERIAL, ReferenceShell, central_gradient, compile_sheet, forces, scene, vertex_forces

DIRECTIONS = ("s00", "s11", "s22")
SIDES = ("p2", "p3", "n2", "n3")
# The compression keys q_d: the tangent along ε_d gains q_d where ε_d < 0.
COMPRESSION_KEYS = [direction + "c" for direction in DIRECTIONS]
KEYS = [direction + side for direction in DIRECTIONS for side in SIDES] + COMPRESSION_KEYS
# Stiffening on both sides of all three directions (Pa), against MATERIAL's s00 = 3e6, s11 = 1.5e6,
# s22 = 2e5: at 10 % strain the added stress is 0.7–2.3 times the linear one. Softening x² terms
# (s00n2 > 0, s11p2 < 0, s22n2 > 0) with x³ terms that turn them round; least tangents
# m = (−1.7e5, −3.0e4, −5.6e3) Pa keep S + diag(m) positive definite.
# The stiffening strains coupled (y0 = ε0 + c01 ε1, y1 = ε1 + c10 ε0) as yarnfit writes them for a
# membrane with s01/s00 = 0.2, s01/s11 = 0.4.
STIFFENING = {
    "s00p2": 2.0e7, "s00p3": 3.0e8, "s00n2": 1.0e7, "s00n3": 2.0e8,
    "s11p2": -6.0e6, "s11p3": 4.0e8, "s11n2": -8.0e6, "s11n3": 1.0e8,
    "s22p2": 2.0e6, "s22p3": 5.0e7, "s22n2": 1.0e6, "s22n3": 6.0e7,
    "c01": 0.2, "c10": 0.4,
}
# Compression terms of both signs (Pa): the weft half as stiff in compression (q0 = −s00/2), the
# warp more than twice as stiff (q1 = 1.33 s11), negative shear at a quarter of s22 (q2 = −0.75
# s22). With STIFFENING's least tangents the least tangent S + Dᵀ diag(m) D + diag(min(q, 0)) has
# entries 00 = 1.3e6, 11 = 1.5e6, 22 = 4.4e4 Pa and a determinant of its normal block of 1.6e12 Pa²:
# convex.
COMPRESSION = {"s00c": -1.5e6, "s11c": 2.0e6, "s22c": -1.5e5}
NONLINEAR = {**STIFFENING, **COMPRESSION}
# Central differences of a smooth energy at 1e-7 m on 0.1 m cells (test_plugin's FD_STEP): truncation
# ~1e-10 relative (φ is C² at 0 and polynomial on each side, so a step across ε_d = 0 adds only a
# jump in the third derivative times the step²), round-off ~ε W/(δ |∇W|) ~ 1e-9; 1e-6 is the
# issue's bound.
GRADIENT_RTOL = 1e-6
# The compression terms are only C¹ at ε_d = 0: a difference step straddling it errs by up to
# ~q δε/4, δε ~ 1e-6 the strain a 1e-7 m step makes on 0.1 m cells, i.e. ~1e-5 of a 6 % strain's
# stress. So no strain (of a triangle or smoothing domain) may lie within this of 0, where the step
# would straddle it; 1e-4 is a hundred steps.
STRAIN_MARGIN = 1e-4
# The compression terms' share of the forces on the distorted flex, or of a uniform patch's
# compressed stress component, must be at least this: 1e4 times the gradient tolerance (and far
# more than the patches'), so that a missing or wrong term fails (measured 1.3–24 % on the flex,
# 3–300 % on the patches).
COMPRESSION_SHARE = 0.01
# Strain rates by central differences along the velocity: the strains are quadratic in the
# positions, so the difference is exact up to round-off ~ε |ε|/step ~ 1e-10 relative.
RATE_STEP = 1e-6
# Strains the distorted flex must reach on both sides of every direction, so that both sides' keys
# are exercised where they matter.
LARGE_STRAIN = 0.05
# The stiffening terms' share of the forces on the distorted flex must be at least this, or the
# comparison would hardly test them.
STIFFENING_SHARE = 0.3
# Force on a vertex of an unstrained sheet (N): round-off of ε ~ 1e-16 times h s ~ 1e3 N/m times a
# cell is ~1e-14 N; 1e-9 N is far below the ~10 N a 1 % strain gives (test_plugin's bound).
UNSTRAINED_FORCE_ATOL = 1e-9
# The same state turned rigidly: positions (~1 m from the origin) and edge vectors (~0.1 m) lose
# ~1e-16 m each when turned, so strains move by ~1e-15 and forces by ~1e-15 relative per
# triangle, summed over six at a vertex; 1e-12 of the largest force is well above that and
# far below any real error (a wrong frame changes them at order 1).
OBJECTIVITY_RTOL = 1e-12
# A uniform strain is an exact solution of linear triangles, so the stress recovered from the
# boundary forces equals the closed form up to round-off: strains of 0.1 from positions of 0.5 m
# carry ~1e-15 relative error, the forces of a boundary vertex sum two or three triangles, and
# F⁻¹ P adds a few ulps; 1e-12 is ample and ~1e11 times smaller than the stiffening terms' share.
PATCH_RTOL = 1e-12
# Force on a vertex inside a uniformly strained patch, relative to the boundary forces: the
# triangles around it cancel exactly up to the same round-off.
INTERIOR_RTOL = 1e-12
# Uniaxial equilibrium (free lateral edges) against the closed form: least-squares tolerance of
# 1e-12 of the force scale amplified by the soft transverse direction (test_plugin_mechanics'
# EXACT_RTOL).
EQUILIBRIUM_RTOL = 1e-8
RESIDUAL_RTOL = 1e-12
# Forces of the plugin before the stiffening terms, recorded at commit 1c53a26 (see the file's
# note). Measured bitwise equal on the machine that recorded them; another libm (atan2 in the
# bending) or compiler may move the last bit of a few terms, each ~1e-16 of the largest force.
STVK_FORCES = Path(__file__).parent / "data" / "plugin_stvk_forces.json"
STVK_RTOL = 1e-14


def coupling_map(coefficients):
    """``D = ∂y/∂ε`` (3, 3) of the stiffening strains."""
    c01, c10 = coefficients.get("c01", 0.0), coefficients.get("c10", 0.0)
    return np.array([[1.0, c01, 0.0], [c10, 1.0, 0.0], [0.0, 0.0, 1.0]])


def compression(coefficients):
    """(q0, q1, q2) (Pa) of the keys ``s00c s11c s22c``."""
    return np.array([coefficients.get(key, 0.0) for key in COMPRESSION_KEYS])


def nonlinear_energy(eps, coefficients):
    """Σ_d φ_d(y_d) + Σ_d ½ q_d min(ε_d, 0)² per triangle or domain (Pa, per unit thickness) for
    strains ``eps (T, 3)``, y = D ε."""
    eps = np.asarray(eps, float)
    y = eps @ coupling_map(coefficients).T
    total = np.zeros(len(y))
    for d, direction in enumerate(DIRECTIONS):
        p2, p3, n2, n3 = (coefficients.get(direction + side, 0.0) for side in SIDES)
        x = y[:, d]
        k2, k3 = np.where(x >= 0, p2, n2), np.where(x >= 0, p3, n3)
        total += k2 * x**3 / 3 + k3 * x**4 / 4
    return total + 0.5 * np.minimum(eps, 0) ** 2 @ compression(coefficients)


def stiffening_stress(eps, coefficients, order=1):
    """φ_d'(y_d) (``order=1``) or φ_d''(y_d) (``order=2``) for strains ``eps (..., 3)`` (Pa), on
    the stiffening strains y = D ε (the stress in ε is Dᵀ of the first)."""
    y = np.asarray(eps, float) @ coupling_map(coefficients).T
    out = np.zeros_like(y)
    for d, direction in enumerate(DIRECTIONS):
        p2, p3, n2, n3 = (coefficients.get(direction + side, 0.0) for side in SIDES)
        x = y[..., d]
        k2, k3 = np.where(x >= 0, p2, n2), np.where(x >= 0, p3, n3)
        out[..., d] = k2 * x**2 + k3 * x**3 if order == 1 else 2 * k2 * x + 3 * k3 * x**2
    return out


def compression_stress(eps, coefficients, order=1):
    """q_d min(ε_d, 0) (``order=1``, the stress) or q_d [ε_d < 0] (``order=2``, the tangent) for
    strains ``eps (..., 3)`` (Pa), on ε itself."""
    eps = np.asarray(eps, float)
    return compression(coefficients) * (np.minimum(eps, 0) if order == 1 else eps < 0)


class StiffeningShell(ReferenceShell):
    """test_plugin's independent reference (StVK membrane and the discrete bending) plus the
    nonlinear terms A h [Σ_d φ_d(y_d) + Σ_d ½ q_d min(ε_d, 0)²] per triangle, or with ``domains``
    (membrane="node", each triangle corner's smoothing domain (T, 3)) per domain at its smoothed
    strain ε_d = Σ over its corners of (A_t/3)/A_d ε_t, A_d the sum of those thirds."""

    def __init__(self, model, material, coefficients, angle=0.0, domains=None):
        super().__init__(model, material, angle, domains=domains)
        self.coefficients = coefficients
        self.h = material["thickness"]

    def membrane_strains(self, x):
        """The strains the nonlinear terms see, (N, 3), and their reference areas (N,): per
        triangle, or per smoothing domain."""
        eps, _ = self.strains(x)
        if self.domains is None:
            return eps, self.area
        share = np.zeros(self.domains.max() + 1)
        np.add.at(share, self.domains.ravel(), np.repeat(self.area / 3, 3))
        smoothed = np.zeros((len(share), 3))
        for k in range(3):
            np.add.at(smoothed, self.domains[:, k], (self.area / 3 / share[self.domains[:, k]])[:, None] * eps)
        return smoothed, share

    def energy(self, x):
        eps, area = self.membrane_strains(x)
        return super().energy(x) + self.h * float(area @ nonlinear_energy(eps, self.coefficients))


def closed_form_stress(eps, coefficients, material=MATERIAL):
    """σ = h (S ε + Dᵀ φ'(D ε) + q min(ε, 0)) (N/m, Voigt) for strains ``eps (3,)``."""
    S = np.array([[material["s00"], material["s01"], 0], [material["s01"], material["s11"], 0],
                  [0, 0, material["s22"]]])
    D = coupling_map(coefficients)
    eps = np.asarray(eps, float)
    return material["thickness"] * (S @ eps + D.T @ stiffening_stress(eps, coefficients)
                                    + compression_stress(eps, coefficients))


def model_with(coefficients=STIFFENING, membrane="triangle", **options):
    extra = {**coefficients, **options.pop("extra", {})}
    if membrane == "triangle":
        return mujoco.MjModel.from_xml_string(scene(extra=extra, **options))
    # scene() writes every value with repr, which quotes a word: the key goes in through the spec.
    spec = mujoco.MjSpec.from_string(scene(extra=extra, **options))
    spec.plugins[0].config = {**spec.plugins[0].config, "membrane": membrane}
    return compile_sheet(spec)


def vertex_dofs(model):
    """(V, 3) dof indices of each vertex's three world-aligned slide joints."""
    return model.body_dofadr[model.flex_vertbodyid][:, None] + np.arange(3)


def qpos_at(model, x):
    """qpos placing the flex's vertices at ``x (V, 3)``."""
    _, rest = forces(model, model.qpos0)
    qpos = model.qpos0.copy()
    qpos[vertex_dofs(model)] = x - rest
    return qpos


def distorted(model, seed=7):
    """qpos of the flex distorted in and out of plane by 6 mm rms on 8–10 cm cells: strains of both
    signs in every direction, rms 6 % (ε0, ε1) and 11 % (ε2), largest 15 % and 27 %."""
    rng = np.random.default_rng(seed)
    return model.qpos0 + 0.006 * rng.standard_normal(model.nq)


# -- forces and damping -----------------------------------------------------------------------------


@pytest.mark.parametrize("angle", [0.0, 0.4])
def test_forces_are_minus_the_gradient_of_the_energy(angle):
    model = model_with(angle=angle)
    qpos = distorted(model)
    qfrc, x = forces(model, qpos)
    reference = StiffeningShell(model, MATERIAL, STIFFENING, angle)
    eps, _ = reference.strains(x)
    # Both sides of every direction are strained well into the nonlinear range.
    assert np.all(eps.max(axis=0) > LARGE_STRAIN) and np.all(eps.min(axis=0) < -LARGE_STRAIN)
    gradient = central_gradient(reference.energy, x)
    np.testing.assert_allclose(vertex_forces(model, qfrc), -gradient, rtol=0,
                               atol=GRADIENT_RTOL * np.abs(gradient).max())
    # ... and the stiffening terms are a large part of these forces.
    linear, _ = forces(mujoco.MjModel.from_xml_string(scene(angle=angle)), qpos)
    assert np.abs(qfrc - linear).max() > STIFFENING_SHARE * np.abs(qfrc).max()


# Compression keys on the distorted flex: (keys, angle). Each key alone, softer and stiffer in
# compression than in tension, then all three with the stiffening and its coupling, on the bias.
COMPRESSED = {
    "weft softer": ({"s00c": -1.5e6}, 0.0),
    "warp stiffer": ({"s11c": 2.0e6}, 0.0),
    "negative shear softer": ({"s22c": -1.5e5}, 0.0),
    "negative shear stiffer": ({"s22c": 3.0e5}, 0.0),
    "all, with stiffening, bias": (NONLINEAR, 0.4),
}


@pytest.mark.parametrize("case", sorted(COMPRESSED))
def test_compression_forces_are_minus_the_gradient_of_the_energy(case):
    """The compression terms h ½ q_d min(ε_d, 0)² act where ε_d < 0 and nowhere else: on a flex
    with strains of both signs in every direction the forces are minus the reference energy's
    gradient."""
    coefficients, angle = COMPRESSED[case]
    model = model_with(coefficients, angle=angle)
    qpos = distorted(model)
    qfrc, x = forces(model, qpos)
    reference = StiffeningShell(model, MATERIAL, coefficients, angle)
    eps, _ = reference.strains(x)
    # Some triangles compressed and others stretched along every direction, none at the kink.
    assert np.all(eps.max(axis=0) > LARGE_STRAIN) and np.all(eps.min(axis=0) < -LARGE_STRAIN)
    assert np.abs(eps).min() > STRAIN_MARGIN
    gradient = central_gradient(reference.energy, x)
    np.testing.assert_allclose(vertex_forces(model, qfrc), -gradient, rtol=0,
                               atol=GRADIENT_RTOL * np.abs(gradient).max())
    without = {k: v for k, v in coefficients.items() if k not in COMPRESSION_KEYS}
    other, _ = forces(model_with(without, angle=angle), qpos)
    assert np.abs(qfrc - other).max() > COMPRESSION_SHARE * np.abs(qfrc).max()


def test_node_membrane_carries_the_nonlinear_terms_on_the_smoothed_strains():
    """membrane="node" (one domain per vertex on the one-panel grid): the stiffening and
    compression terms act on each domain's smoothed strain, and the forces are minus the gradient
    of the reference energy over those domains."""
    model = model_with(NONLINEAR, membrane="node", angle=0.4)
    qpos = distorted(model)
    qfrc, x = forces(model, qpos)
    reference = StiffeningShell(model, MATERIAL, NONLINEAR, 0.4, domains=model.flex_elem.reshape(-1, 3))
    smoothed, _ = reference.membrane_strains(x)
    assert np.all(smoothed.max(axis=0) > 0) and np.all(smoothed.min(axis=0) < 0)
    assert np.abs(smoothed).min() > STRAIN_MARGIN
    gradient = central_gradient(reference.energy, x)
    np.testing.assert_allclose(vertex_forces(model, qfrc), -gradient, rtol=0,
                               atol=GRADIENT_RTOL * np.abs(gradient).max())
    other, _ = forces(model_with(STIFFENING, membrane="node", angle=0.4), qpos)
    assert np.abs(qfrc - other).max() > COMPRESSION_SHARE * np.abs(qfrc).max()


@pytest.mark.parametrize("coefficients", [STIFFENING, NONLINEAR], ids=["stiffening", "with compression"])
def test_damping_is_the_tangent_times_the_strain_rate(coefficients):
    """With damping β the forces gain −β Jεᵀ A h (S + Dᵀ diag φ''(y) D + diag q_d [ε_d < 0]) Jε v
    − β Jκᵀ A h³ B Jκ v. Reference: the strain rates J v by central differences of the reference
    strains, then Jᵀ(stress) as the gradient of the work of that fixed stress."""
    beta = 0.01  # s
    model = model_with(coefficients, extra={"damping": beta})
    rng = np.random.default_rng(11)
    qpos = distorted(model)
    qvel = rng.standard_normal(model.nv)
    damped, x = forces(model, qpos, qvel)
    elastic, _ = forces(model, qpos)
    reference = StiffeningShell(model, MATERIAL, coefficients)
    v = vertex_forces(model, qvel)
    plus, minus = reference.strains(x + RATE_STEP * v), reference.strains(x - RATE_STEP * v)
    eps_rate, kappa_rate = ((p - m) / (2 * RATE_STEP) for p, m in zip(plus, minus))
    eps, _ = reference.strains(x)
    tangent = reference.h * stiffening_stress(eps, coefficients, order=2)  # (T, 3) on y, N/m
    compressed = reference.h * compression_stress(eps, coefficients, order=2)  # (T, 3) on ε, N/m
    D = coupling_map(coefficients)
    stress = reference.area[:, None] * (eps_rate @ reference.S + (tangent * (eps_rate @ D.T)) @ D
                                        + compressed * eps_rate)
    moment = reference.area[:, None] * (kappa_rate @ reference.B)

    def work(y):
        e, k = reference.strains(y)
        return float(np.sum(stress * e) + np.sum(moment * k))

    expected = -beta * central_gradient(work, x)
    got = vertex_forces(model, damped - elastic)
    np.testing.assert_allclose(got, expected, rtol=0, atol=GRADIENT_RTOL * np.abs(expected).max())
    assert float(np.sum(got * v)) < 0  # it dissipates: the tangent is positive definite (convexity)


# -- rigid motions ----------------------------------------------------------------------------------


# A rigid motion: shift (m), angular velocity (rad/s) and velocity (m/s).
SHIFT = np.array([0.1, -0.2, 0.3])
SPIN = np.array([0.3, -1.1, 0.7])
VELOCITY = np.array([0.2, 0.5, -0.4])


def rotation():
    turn = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    tilt = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(0.7), -math.sin(0.7)], [0.0, math.sin(0.7), math.cos(0.7)]])
    return turn @ tilt


def test_rigid_motions_of_the_rest_mesh_carry_no_force():
    model = model_with(NONLINEAR, extra={"damping": 0.01})
    _, rest = forces(model, model.qpos0)
    moved = rest @ rotation().T + SHIFT
    qvel = np.zeros(model.nv)  # moving rigidly too
    qvel[vertex_dofs(model)] = np.cross(SPIN, moved) + VELOCITY
    qfrc, _ = forces(model, qpos_at(model, moved), qvel)
    assert np.abs(qfrc).max() < UNSTRAINED_FORCE_ATOL


def test_forces_turn_with_a_rigid_motion_of_a_strained_mesh():
    """Frame indifference at large strain: the strained flex turned and shifted has its forces
    turned, and a rigid velocity field on it adds no damping force."""
    model = model_with(NONLINEAR, extra={"damping": 0.01})
    dofs = vertex_dofs(model)
    qfrc, x = forces(model, distorted(model))
    R = rotation()
    turned, _ = forces(model, qpos_at(model, x @ R.T + SHIFT))
    scale = np.abs(qfrc).max()
    np.testing.assert_allclose(turned[dofs], qfrc[dofs] @ R.T, rtol=0, atol=OBJECTIVITY_RTOL * scale)
    qvel = np.zeros(model.nv)
    qvel[dofs] = np.cross(SPIN, x) + VELOCITY
    spinning, _ = forces(model, qpos_at(model, x), qvel)
    np.testing.assert_allclose(spinning, qfrc, rtol=0, atol=OBJECTIVITY_RTOL * scale)


# -- patches ----------------------------------------------------------------------------------------

# Uniform in-plane deformation gradients (world = material frame at angle 0), each with strains
# where the stiffening terms are a large part of the stress.
PATCHES = {
    "uniaxial weft": [[1.15, 0.0], [0.0, 1.0]],
    "uniaxial warp compressed": [[1.0, 0.0], [0.0, 0.88]],
    "biaxial": [[1.12, 0.0], [0.0, 1.10]],
    "biaxial mixed": [[1.12, 0.0], [0.0, 0.90]],
    "shear": [[1.0, 0.3], [0.0, 1.0]],
    "shear reversed": [[1.0, -0.3], [0.0, 1.0]],
}


def patch_stress(model, F):
    """The stress (Voigt, N/m) and strain ε (3,) of the flex under the uniform in-plane deformation
    x = F X. Linear triangles hold it exactly: the force on a vertex of the right edge (x = max, not
    a corner) is −Δy P e_x, on one of the top edge −Δx P e_y, zero inside, with P = F Σ the first
    Piola stress, so Σ = F⁻¹ [P e_x, P e_y]. Checks on the way that Σ is symmetric, every boundary
    vertex alike, and no force inside or out of plane."""
    _, rest = forces(model, model.qpos0)
    x = rest.copy()
    x[:, :2] = rest[:, :2] @ F.T
    qfrc, _ = forces(model, qpos_at(model, x))
    f = qfrc[vertex_dofs(model)]
    dx, dy = (np.diff(np.unique(rest[:, i]))[0] for i in (0, 1))
    low_x, high_x = np.isclose(rest[:, 0], rest[:, 0].min()), np.isclose(rest[:, 0], rest[:, 0].max())
    low_y, high_y = np.isclose(rest[:, 1], rest[:, 1].min()), np.isclose(rest[:, 1], rest[:, 1].max())
    right_edge, top_edge = high_x & ~(low_y | high_y), high_y & ~(low_x | high_x)
    inside = ~(low_x | high_x | low_y | high_y)
    P = np.column_stack([-f[right_edge, :2].mean(axis=0) / dy, -f[top_edge, :2].mean(axis=0) / dx])
    Sigma = np.linalg.solve(F, P)
    measured = np.array([Sigma[0, 0], Sigma[1, 1], Sigma[0, 1]])
    E = 0.5 * (F.T @ F - np.eye(2))
    eps = np.array([E[0, 0], E[1, 1], 2 * E[0, 1]])
    assert abs(Sigma[1, 0] - Sigma[0, 1]) < PATCH_RTOL * np.abs(measured).max()  # a symmetric Σ, as it must be
    # Every boundary vertex alike, nothing inside, no force out of plane.
    force_scale = np.abs(f).max()
    for edge in (right_edge, top_edge):
        np.testing.assert_allclose(f[edge], np.broadcast_to(f[edge][0], f[edge].shape), rtol=0,
                                   atol=INTERIOR_RTOL * force_scale)
    assert np.abs(f[inside]).max() < INTERIOR_RTOL * force_scale
    assert np.abs(f[:, 2]).max() < INTERIOR_RTOL * force_scale
    return measured, eps


@pytest.mark.parametrize("case", sorted(PATCHES))
def test_uniform_patch_matches_the_closed_form_stress(case):
    """A uniform deformation's stress (:func:`patch_stress`) against the closed form
    σ = h (S ε + Dᵀ φ'(D ε))."""
    measured, eps = patch_stress(model_with(), np.array(PATCHES[case]))
    expected = closed_form_stress(eps, STIFFENING)
    np.testing.assert_allclose(measured, expected, rtol=0, atol=PATCH_RTOL * np.abs(expected).max())
    # The stiffening terms carry a large part of the stress in the loaded direction.
    linear = closed_form_stress(eps, {})
    loaded = np.argmax(np.abs(expected))
    assert abs(expected[loaded] - linear[loaded]) > STIFFENING_SHARE * abs(expected[loaded])


# Uniform deformations with one Voigt strain negative: (F, that direction). Weft compressed alone
# (ε = (−0.095, 0, 0)), warp compressed with the weft stretched (ε = (0.105, −0.095, 0)), shear
# reversed (ε = (0, 0.045, −0.3)).
COMPRESSED_PATCHES = {
    "weft compressed": ([[0.9, 0.0], [0.0, 1.0]], 0),
    "warp compressed, weft stretched": ([[1.1, 0.0], [0.0, 0.9]], 1),
    "shear reversed": ([[1.0, -0.3], [0.0, 1.0]], 2),
}


@pytest.mark.parametrize("coefficients", [COMPRESSION, NONLINEAR], ids=["compression", "with stiffening"])
@pytest.mark.parametrize("case", sorted(COMPRESSED_PATCHES))
def test_compressed_patch_gains_q_times_the_compressive_strain(case, coefficients):
    """In a uniform state the compression terms add h q_d ε_d to the stress component whose strain
    is negative, and nothing to the others: with the compression keys alone the weft-compressed
    patch carries σ0 = h (s00 ε0 + s01 ε1 + q0 ε0), σ1 = h (s01 ε0 + s11 ε1)."""
    F, direction = COMPRESSED_PATCHES[case]
    measured, eps = patch_stress(model_with(coefficients), np.array(F))
    assert eps[direction] < 0 and np.all(np.delete(eps, direction) >= 0)
    h, q = MATERIAL["thickness"], compression(coefficients)
    without = {k: v for k, v in coefficients.items() if k not in COMPRESSION_KEYS}
    added = np.zeros(3)
    added[direction] = h * q[direction] * eps[direction]
    expected = closed_form_stress(eps, without) + added
    np.testing.assert_allclose(measured, expected, rtol=0, atol=PATCH_RTOL * np.abs(expected).max())
    assert abs(added[direction]) > COMPRESSION_SHARE * abs(expected[direction])


def uniaxial_prediction(direction, strain):
    """Uniaxial stress along weft (0) or warp (1) at engineering strain ``strain`` with the
    transverse direction free: F = diag(1 + strain, λ) in (loaded, transverse) axes, λ from
    σ_transverse = 0 (one root: s_tt + φ_t'' > 0 by convexity, so σ_t is increasing in E_t).
    Returns the tension P = (1 + strain) σ_loaded (N/m) and λ."""
    loaded = 0.5 * ((1 + strain) ** 2 - 1)

    def stress(transverse):
        eps = np.zeros(3)
        eps[direction], eps[1 - direction] = loaded, transverse
        return closed_form_stress(eps, STIFFENING)

    transverse = brentq(lambda e: stress(e)[1 - direction], -0.4, 0.4, xtol=1e-16, rtol=1e-15)
    return (1 + strain) * stress(transverse)[direction], math.sqrt(1 + 2 * transverse)


@pytest.mark.parametrize("direction", [0, 1])
def test_uniaxial_pull_matches_the_closed_form(direction):
    """A strip between clamps (x fixed, y free) at 10 % strain along weft (angle 0) or warp
    (angle π/2), lateral edges free, in equilibrium under MuJoCo's passive forces (as
    test_plugin_mechanics does for StVK): clamp force per width and lateral contraction against
    :func:`uniaxial_prediction`."""
    strain = 0.10
    model = model_with(angle=[0.0, math.pi / 2][direction], count="7 4 1")
    dofs = vertex_dofs(model)
    _, rest = forces(model, model.qpos0)
    width = np.ptp(rest[:, 1])
    left, right = np.isclose(rest[:, 0], rest[:, 0].min()), np.isclose(rest[:, 0], rest[:, 0].max())
    free_x = ~(left | right)
    x0 = rest[:, 0].min()

    def place(u):
        x = rest.copy()
        x[:, 0] = x0 + (rest[:, 0] - x0) * (1 + strain)
        x[free_x, 0] = u[:free_x.sum()]
        x[:, 1] = u[free_x.sum():]
        return x

    def vertex(u):
        return forces(model, qpos_at(model, place(u)))[0][dofs]

    def residual(u):
        f = vertex(u)
        return np.concatenate([f[free_x, 0], f[:, 1]])

    guess = np.concatenate([x0 + (rest[free_x, 0] - x0) * (1 + strain), rest[:, 1]])
    solution = least_squares(residual, guess, xtol=1e-15, ftol=1e-15, gtol=1e-15, method="lm")
    x = place(solution.x)
    tension = -vertex(solution.x)[right, 0].sum() / width
    assert np.abs(residual(solution.x)).max() < RESIDUAL_RTOL * tension * width
    columns = np.unique(rest[:, 0])
    middle = np.isclose(rest[:, 0], columns[len(columns) // 2])
    contraction = np.ptp(x[middle, 1]) / width
    expected_tension, expected_lambda = uniaxial_prediction(direction, strain)
    assert tension == pytest.approx(expected_tension, rel=EQUILIBRIUM_RTOL)
    assert contraction == pytest.approx(expected_lambda, rel=EQUILIBRIUM_RTOL)


# -- configuration ----------------------------------------------------------------------------------

BAD = {
    "not finite": ({"s11n2": float("nan")}, "config key 's11n2' must be a finite number"),
    "infinite": ({"s22p3": float("inf")}, "config key 's22p3' must be a finite number"),
    "negative quartic": ({"s11n3": -1.0}, "config key 's11n3' must be >= 0"),
    "softening cubic, no quartic, tension": ({"s00p2": -1.0e6}, r"'s00p2' = -1e\+06 softens the positive strain "
                                             r"side without bound because 's00p3' = 0"),
    "softening cubic, no quartic, compression": ({"s22n2": 1.0e6, "s22p3": 1.0e8},
                                                 "'s22n2' = 1e\\+06 softens the negative strain side without "
                                                 "bound because 's22n3' = 0"),
    # m1 = −(5e7)²/(3 · 1e8) = −8.3e6 Pa against s11 = 1.5e6.
    "not convex, warp": ({"s11p2": -5.0e7, "s11p3": 1.0e8},
                         r"non-convex.*'s11p2' = -5e\+07 and 's11p3' = 1e\+08 give m1 = -8\.33333e\+06.*"
                         r"11 entry = -6\.83333e\+06"),
    # Each direction positive alone (s00 + m0 = 1e6, s11 + m1 = 2e5) but not the coupled pair:
    # (s00 + m0)(s11 + m1) = 2e11 < s01² = 3.6e11.
    "not convex, coupled": ({"s00n2": 2.0e7, "s00n3": 6.6666666666666667e7, "s11n2": 1.3e7, "s11n3": 4.3333333333333333e7},
                            r"non-convex.*'s00n2' = 2e\+07 and 's00n3' = 6\.66667e\+07 give m0 = -2e\+06; "
                            r"'s11n2' = 1\.3e\+07 and 's11n3' = 4\.33333e\+07 give m1 = -1\.3e\+06.*"
                            r"determinant of the normal block = -1\.6e\+11"),
    # With coupled stiffening strains the least tangent is S + Dᵀ diag(m) D: m0 = −2e6 alone
    # (s00 + m0 = 1e6 > 0) fails once c10 = 1 carries m1 = −1.3e6 into the 00 entry too.
    "not convex, coupled strains": ({"s11n2": 1.3e7, "s11n3": 4.3333333333333333e7, "c01": 0.0, "c10": 2.0},
                                    r"non-convex.*c10 = 2.*'s11n2' = 1\.3e\+07.*00 entry = -2\.2e\+06"),
    "not convex, shear": ({"s22p2": -1.0e7, "s22p3": 1.0e8}, r"non-convex.*'s22p2' = -1e\+07 and 's22p3' = 1e\+08 "
                          r"give m2 = -333333.*22 entry = -133333"),
    "compression not finite": ({"s11c": float("nan")}, "config key 's11c' must be a finite number"),
    # The least tangent gains diag(min(q, 0)): s00 + q0 = −5e5.
    "not convex, weft compression": ({"s00c": -3.5e6}, r"non-convex.*'s00c' = -3\.5e\+06; then its 00 entry = -500000"),
    # s11 + q1 = 1e5 > 0 alone, but s00 (s11 + q1) = 3e11 < s01² = 3.6e11.
    "not convex, coupled compression": ({"s11c": -1.4e6}, r"non-convex.*'s11c' = -1\.4e\+06.*"
                                        r"determinant of the normal block = -6e\+10"),
    "not convex, negative shear": ({"s22c": -2.5e5}, r"non-convex.*'s22c' = -250000; .*22 entry = -50000"),
    # Neither alone (s22 + m2 = 1.7e5, s22 + q2 = 2e4) but both: both named.
    "not convex, softening and compression": ({"s22n2": 3.0e6, "s22n3": 1.0e8, "s22c": -1.8e5},
                                              r"non-convex.*'s22n2' = 3e\+06 and 's22n3' = 1e\+08 give m2 = -30000; "
                                              r"'s22c' = -180000.*22 entry = -10000"),
    # With STIFFENING and its coupling: 00 entry s00 + m0 + c10² m1 + q0 = 3e6 − 1.67e5 − 4.8e3 − 2.9e6.
    "not convex, compression with stiffening": ({**STIFFENING, "s00c": -2.9e6},
                                                r"non-convex.*c01 = 0\.2, c10 = 0\.4; 's00n2' = 1e\+07 and "
                                                r"'s00n3' = 2e\+08 give m0 = -166667; 's00c' = -2\.9e\+06.*"
                                                r"00 entry = -71466\.7"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_stiffening_keys_fail_compilation_naming_the_key(case):
    keys, message = BAD[case]
    with pytest.raises(ValueError, match=message):
        model_with(keys)


def test_softening_within_convexity_compiles():
    """The bound is S + diag(m) positive definite, not every k2 ≥ 0: a softening x² term held by
    its x³ term compiles (m1 = −(5e6)²/(3 · 1e7) = −8.3e5 against s11 = 1.5e6), and so does a
    negative compression key within it (s00 + q0 = 5e5, (s00 + q0) s11 = 7.5e11 > s01² = 3.6e11)."""
    assert model_with({"s11p2": -5.0e6, "s11p3": 1.0e7}).nplugin == 1
    assert model_with({"s00c": -2.5e6}).nplugin == 1


# -- all keys 0 ------------------------------------------------------------------------------------


def test_all_keys_zero_is_the_stvk_plugin_as_it_was():
    """Without stiffening or compression the membrane is the StVK one: forces (with damping, on the
    bias) equal those the plugin gave before the keys existed, and keys given as 0 (the compression
    keys too) equal keys left out."""
    record = json.loads(STVK_FORCES.read_text())
    qpos, qvel = np.array(record["qpos"]), np.array(record["qvel"])
    options = {"angle": record["angle"], "extra": {"damping": record["damping"]}}
    absent = mujoco.MjModel.from_xml_string(scene(record["material"], **options))
    zeros = mujoco.MjModel.from_xml_string(scene(record["material"], angle=record["angle"],
                                                 extra={"damping": record["damping"], **dict.fromkeys(KEYS, 0.0)}))
    before = np.array(record["qfrc_passive"])
    now = forces(absent, qpos, qvel)[0]
    np.testing.assert_allclose(now, before, rtol=0, atol=STVK_RTOL * np.abs(before).max())
    np.testing.assert_array_equal(forces(zeros, qpos, qvel)[0], now)


def test_the_plugin_law_is_yarnfits_shell_law():
    """The stress this file checks the plugin against is ShellMaterial's with the same keys: what
    the fit fits is what MuJoCo simulates."""
    from yarnfit.shell import NonlinearMembrane, ShellMaterial

    shell = ShellMaterial(MATERIAL["thickness"], **{k: MATERIAL[k] for k in ("s00", "s01", "s11", "s22")},
                          b00=1.0, b01=0.0, b11=1.0, b22=1.0, nonlinear=NonlinearMembrane.from_keys(NONLINEAR))
    rng = np.random.default_rng(5)
    for eps in rng.uniform(-0.15, 0.15, size=(20, 3)):
        I = np.array([[1 + 2 * eps[0], eps[2]], [eps[2], 1 + 2 * eps[1]]])
        gradient, _ = shell.energy_gradient(I, np.zeros((2, 2)))
        # dW/dI = (h/2) [[σ0, σ2], [σ2, σ1]] with σ the stress per thickness.
        stress = np.array([gradient[0, 0], gradient[1, 1], gradient[0, 1]]) * 2.0
        np.testing.assert_allclose(stress, closed_form_stress(eps, NONLINEAR), rtol=1e-12,
                                   atol=1e-12 * np.abs(stress).max())
