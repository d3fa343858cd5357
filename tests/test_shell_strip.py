"""The shell strip between jaws (yarnfit.validate.shell_strip): closed forms, an independent
minimiser (the long strip's middle against ShellMaterial.uniaxial_pull), derivatives against
differences, the mesh following the yarns, and mesh convergence."""

import math

import numpy as np
import pytest

from yarnfit.shell import RidgeMembrane, ShellMaterial
from yarnfit.validate.shell_strip import (
    STRAIN_STEP,
    _Membrane,
    pull_shell_strip,
    richardson_limit,
    shell_strip_limit,
    strip_mesh,
)

H = 5e-4  # m
GAUGE, WIDTH = 8e-3, 6e-3  # m: an 8 x 6 strip of 1 mm repeats
ANGLES = (0.0, 45.0, 90.0, -45.0)
# A homogeneous state is exact on a linear-triangle mesh: what is left is the round-off of the
# energy's gradient summed over a jaw's nodes.
HOMOGENEOUS_RTOL = 1e-9
# A strip eight widths long: its jaws constrain ends a width or so long, and its middle half is
# read three widths from them. Measured: the woven-like material's middle within 0.4 % of the
# free pull at its middle's strain at 45° (0.0 % at 0°); the bound leaves the mesh's error room.
LONG_STRIP_RTOL = 0.01
# Central differences of the energy (gradient) and of the gradient (stiffness) at a step of 1e-9 m
# on millimetre strips: truncation ~1e-10 relative, round-off ~1e-7 of the largest entry.
DERIVATIVE_RTOL = 1e-5
# The woven-like bias strip's middle pull at 2 / 5 %, extrapolated from 12 and 24 rows against the
# same from 24 and 48: measured 4.0 / 4.8 % (from 48 and 96 rows it moves another 2.3 / 2.0 %: the
# extrapolation converges, a little slower than first order).
EXTRAPOLATION_RTOL = 0.06


def isotropic_without_poisson(young_pa: float = 1e6) -> ShellMaterial:
    """Isotropic StVK with ν = 0: a clamped strip pulled along any axis stays homogeneous."""
    return ShellMaterial(H, young_pa, 0.0, young_pa, 0.5 * young_pa, 1.0, 0.0, 1.0, 1.0)


def woven_like() -> ShellMaterial:
    """A woven's membrane: stiff weft and warp, shear 1e-4 of them that stiffens past 2 %."""
    ridge = RidgeMembrane(base=(2e8, 2e6, 1.5e8, 2e4),
                          ridges=((0.0, 0.0, 1.0, 0.02, 5e5), (0.0, 0.0, -1.0, 0.02, 5e5),
                                  (1.0, 0.0, 0.0, 0.0, 1e9), (0.0, 1.0, 0.0, 0.0, 1e9)))
    return ShellMaterial(H, 2e8, 2e6, 1.5e8, 2e4, 1.0, 0.0, 1.0, 1.0, nonlinear=ridge)


@pytest.mark.parametrize("angle", ANGLES)
def test_poisson_free_strip_pulls_homogeneously(angle):
    """ν = 0: every jaw strain is a homogeneous uniaxial strain, N = h s00 E λ exactly, read alike
    at the jaws and in the middle, the middle strained as the jaws, the width unchanged."""
    material = isotropic_without_poisson()
    curve = pull_shell_strip(material, angle, GAUGE, WIDTH, [0.02, 0.1])
    assert curve.converged
    for strain in (0.02, 0.1):
        state = curve.at_strain(strain)
        stretch = 1.0 + strain
        exact = H * material.s00 * 0.5 * (stretch**2 - 1.0) * stretch
        assert state.force_n_per_m == pytest.approx(exact, rel=HOMOGENEOUS_RTOL)
        assert state.middle_force_n_per_m == pytest.approx(exact, rel=HOMOGENEOUS_RTOL)
        assert state.mid_strain == pytest.approx(strain, rel=HOMOGENEOUS_RTOL)
        assert state.middle_compression_ratio == pytest.approx(1.0, abs=HOMOGENEOUS_RTOL)
        assert state.compression_ratio == pytest.approx(1.0, abs=HOMOGENEOUS_RTOL)
    # Load steps no longer than STRAIN_STEP, the rest state first.
    strains = [s.strain for s in curve.states]
    assert strains[0] == 0.0 and np.all(np.diff(strains) <= STRAIN_STEP * (1 + 1e-12))


@pytest.mark.parametrize("angle", (0.0, 45.0))
def test_long_strip_middle_is_the_free_pull(angle):
    """Far from its jaws a long strip is the free uniaxial pull (ShellMaterial.uniaxial_pull, an
    independent minimiser of the same energy): force and width at the middle's strain."""
    material = woven_like()
    curve = pull_shell_strip(material, angle, 8 * WIDTH / 4, WIDTH / 4, [0.05], rows=8)
    assert curve.converged
    state = curve.at_strain(0.05)
    free = material.uniaxial_pull(math.radians(angle), 1.0 + state.mid_strain)
    assert state.middle_force_n_per_m == pytest.approx(free.force_n_per_m, rel=LONG_STRIP_RTOL)
    assert state.middle_compression_ratio == pytest.approx(free.width_ratio, abs=LONG_STRIP_RTOL)


def test_gradient_and_stiffness_are_the_energy_derivatives():
    """∂Π/∂u and ∂²Π/∂u² against central differences, at a sheared, stretched state that crosses
    the ridges' knots nowhere near a difference step."""
    material = woven_like()
    mesh = strip_mesh(45.0, 2e-3, 1.5e-3, rows=4)
    membrane = _Membrane(material, mesh, 45.0)
    rng = np.random.default_rng(3)
    u = 0.03 * np.column_stack([mesh.rest[:, 0], -0.4 * mesh.rest[:, 1]]) + 1e-5 * rng.standard_normal(mesh.rest.shape)
    gradient = membrane.gradient(u).ravel()
    stiffness = membrane.stiffness(u).toarray()
    step = 1e-9
    numeric_gradient, numeric_stiffness = np.zeros_like(gradient), np.zeros_like(stiffness)
    for k in range(u.size):
        plus, minus = u.ravel().copy(), u.ravel().copy()
        plus[k] += step
        minus[k] -= step
        numeric_gradient[k] = (membrane.energy(plus.reshape(u.shape)) - membrane.energy(minus.reshape(u.shape))) / (2 * step)
        numeric_stiffness[:, k] = (membrane.gradient(plus.reshape(u.shape)).ravel()
                                   - membrane.gradient(minus.reshape(u.shape)).ravel()) / (2 * step)
    assert np.abs(numeric_gradient - gradient).max() <= DERIVATIVE_RTOL * np.abs(gradient).max()
    assert np.abs(numeric_stiffness - stiffness).max() <= DERIVATIVE_RTOL * np.abs(stiffness).max()


@pytest.mark.parametrize("angle, directions", [(0.0, {0, 90, 135}), (90.0, {0, 90, 135}),
                                               (45.0, {0, 45, 135, 90}), (-45.0, {0, 45, 135, 90})])
def test_mesh_edges_follow_the_yarns(angle, directions):
    """Edges lie along the strip (x) and its yarns: weft and warp at ``−angle`` and ``90 − angle``
    (a bias mesh's half cells at the jaws add edges across, along 90°), never elsewhere; the mesh
    covers the gauge exactly."""
    mesh = strip_mesh(angle, GAUGE, WIDTH)
    t = mesh.triangles
    for a, b in ((0, 1), (1, 2), (2, 0)):
        d = mesh.rest[t[:, b]] - mesh.rest[t[:, a]]
        degrees = np.round(np.degrees(np.arctan2(d[:, 1], d[:, 0])) % 180.0, 6) % 180.0
        assert set(np.unique(degrees)) <= directions
    d1, d2 = mesh.rest[t[:, 1]] - mesh.rest[t[:, 0]], mesh.rest[t[:, 2]] - mesh.rest[t[:, 0]]
    area = 0.5 * (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])
    assert np.all(area > 0)
    assert area.sum() == pytest.approx(GAUGE * WIDTH, rel=1e-12)
    assert np.allclose(mesh.rest[mesh.moving, 0], 0.5 * GAUGE) and np.allclose(mesh.rest[mesh.fixed, 0], -0.5 * GAUGE)


@pytest.mark.parametrize("angle", (0.0, 45.0))
def test_a_short_strip_gets_its_rows_along_the_gauge(angle):
    """A strip shorter than wide (2 x 5 cm) gets ``rows`` node spacings along its gauge, as a
    longer one gets across its width."""
    mesh = strip_mesh(angle, 0.02, 0.05, rows=12)
    assert np.diff(np.unique(np.round(mesh.rest[:, 0], 12))) == pytest.approx(0.02 / 12)
    assert np.ptp(mesh.rest, axis=0) == pytest.approx([0.02, 0.05])  # the whole strip
    d1, d2 = (mesh.rest[mesh.triangles[:, k]] - mesh.rest[mesh.triangles[:, 0]] for k in (1, 2))
    assert 0.5 * (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]).sum() == pytest.approx(0.02 * 0.05, rel=1e-12)
    long = strip_mesh(angle, 0.08, 0.05, rows=12)
    assert np.diff(np.unique(np.round(long.rest[:, 1], 12))) == pytest.approx(0.05 / 12)


def test_bias_strip_converges_with_the_mesh():
    """A woven-like bias strip held by its jaws: its middle strains more than their travel (the
    jaws hold its ends unsheared); its middle pull falls with each doubling of the rows (a
    coarse mesh is stiffer: it spreads the shear bands from the jaws' corners over its cells), and
    the limit extrapolated from 12, 24 and 48 rows is within EXTRAPOLATION_RTOL of that from 6, 12
    and 24."""
    material = woven_like()
    one_mesh = {}
    for rows in (6, 12, 24, 48):
        curve = pull_shell_strip(material, 45.0, GAUGE, WIDTH, [0.02, 0.05], rows=rows)
        one_mesh[rows] = np.array([curve.at_strain(e).middle_force_n_per_m for e in (0.02, 0.05)])
        assert curve.at_strain(0.05).mid_strain > 0.05
    assert np.all(one_mesh[12] > one_mesh[24]) and np.all(one_mesh[24] > one_mesh[48])
    limits = {}
    for rows in (12, 24):
        curve = shell_strip_limit(material, 45.0, GAUGE, WIDTH, [0.02, 0.05], rows=rows)
        assert curve.rows == (rows // 2, rows, 2 * rows) and curve.converged
        limits[rows] = np.array([curve.at_strain(e).middle_force_n_per_m for e in (0.02, 0.05)])
        expected = [richardson_limit(*(one_mesh[n][k] for n in curve.rows)) for k in range(2)]
        assert np.allclose(limits[rows], expected, rtol=1e-12)
    assert np.all(np.abs(limits[24] / limits[12] - 1) <= EXTRAPOLATION_RTOL)


@pytest.mark.parametrize("order", [1.0, 1.5, 2.0, 3.0])
def test_richardson_limit_is_exact_for_a_power_of_the_cell(order):
    """Readings ``L + C h^p`` on cells h, h/2, h/4 give L exactly for any order p >= 1."""
    limit, scale = 3.0, -0.7
    coarse, middle, fine = (limit + scale * h**order for h in (1.0, 0.5, 0.25))
    assert richardson_limit(coarse, middle, fine) == pytest.approx(limit, rel=1e-13)


def test_richardson_limit_is_first_order_where_the_meshes_show_less():
    """An order below 1 or readings that do not converge monotonically: ``2 fine − middle``."""
    coarse, middle, fine = (1.0 + h**0.5 for h in (1.0, 0.5, 0.25))
    assert richardson_limit(coarse, middle, fine) == 2 * fine - middle
    assert richardson_limit(1.0, 1.2, 1.1) == 2 * 1.1 - 1.2
    assert richardson_limit(1.0, 1.0, 1.0) == 1.0


def test_strip_is_read_off_its_load_steps():
    """ShellStripCurve.read reads the middle at its own strains as a yarn strip's curve is read:
    at a load step's middle strain, that step's pull and width."""
    curve = pull_shell_strip(woven_like(), 45.0, GAUGE, WIDTH, [0.02], rows=12)
    state = curve.states[2]
    reading = curve.read([state.mid_strain])[0]
    assert reading.force_n_per_m == pytest.approx(state.middle_force_n_per_m, rel=1e-12)
    assert reading.compression_ratio == pytest.approx(state.middle_compression_ratio, rel=1e-12)
    assert curve.read([0.5])[0] is None  # beyond what the middle reached


@pytest.mark.parametrize("kwargs, message", [
    (dict(angle_deg=30.0), "follows its yarns"),
    (dict(strains=[0.05, 0.02]), "ascending"),
    (dict(strains=[]), "ascending"),
    (dict(gauge=-1.0), "gauge"),
    (dict(width=float("nan")), "width"),
    (dict(rows=1), "rows"),
    (dict(strain_step=0.0), "strain_step"),
])
def test_bad_input_is_refused(kwargs, message):
    arguments = dict(material=isotropic_without_poisson(), angle_deg=0.0, gauge=GAUGE, width=WIDTH, strains=[0.02])
    arguments.update(kwargs)
    with pytest.raises(ValueError, match=message):
        pull_shell_strip(**arguments)


@pytest.mark.parametrize("rows", [2, 5, 4.0])
def test_limit_needs_an_even_count_of_rows(rows):
    """The limit's coarsest mesh has rows / 2 rows: an odd count, or fewer than 4, is refused."""
    with pytest.raises(ValueError, match="even integer"):
        shell_strip_limit(isotropic_without_poisson(), 0.0, GAUGE, WIDTH, [0.02], rows=rows)
