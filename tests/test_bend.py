"""Bends at zero membrane force (:mod:`yarnfit.homogenize.bend`).

References: the closed form of two straight yarns of a linear fibre at different heights bent
about their neutral surface; the central difference of re-solved samples' Ū for the slopes on a
curved tiling; the flat tiling's own slope; and Nelder–Mead (scipy) over the same three membrane
strains as an independent minimiser of the same energy.
"""

import functools
import math

import numpy as np
import pytest
import scipy.optimize

from yarnfit.engine import QuasiStaticOptions, Residual
from yarnfit.fabric import Fabric
from yarnfit.fabric_fit import relax_for_fit
from yarnfit.fibers import Fiber, get_fiber
from yarnfit.homogenize import sample_groups, solve_group, solve_sample
from yarnfit.homogenize.bend import _search_bend, fabric_reach, membrane_form
from yarnfit.homogenize.equilibrium import (
    MAX_ITERATIONS,
    _green_slope,
    _solve_near,
    _solve_with_continuation,
    _surface_green_slope,
)
from yarnfit.homogenize.surface import CarriedEquilibrium
from yarnfit.patterns import YarnPattern
from yarnfit.relax import relax_pattern
from yarnfit.samples import (SMALLEST_CURVATURE, Family, SampleRanges, SampleResult, SampleSpec, free_rest_sample,
                             magnitudes, sample_design)
from yarnfit.yarn import YarnConstruction

# The closed form of straight yarns bent about their neutral surface: the rod's bending is exact
# on a cylinder, and the stretch is quadratic in the engineering strain, which differs from the
# first-order place of the neutral surface by ~h κ (1e-3 of it at 20 /m). Measured: ±0.26 %.
NEUTRAL_RTOL = 0.01
# The neutral surface's offset (from the free strain along the curvature, E00 = z κ to first
# order) against midway between the two yarns: its first-order place, within the product terms
# and the search's stopping slope. Measured: 1.2 % at ±20 /m.
OFFSET_RTOL = 0.02
# The slope on a curved tiling against the central difference of two re-solved samples at ±1e-5
# of Green strain: no contacts between the straight yarns, so both differentiate the rods' energy
# only; the difference's truncation (Ū‴ δ² / 6) and the solves' residuals (1e-8 of the force) are
# ~1e-6 of it. Measured: 2e-8.
SURFACE_SLOPE_RTOL = 1e-5
# The same path on a flat tiling, retiled rather than mapped linearly (:func:`_green_slope`): the
# two differ only in round-off of the surface maps. Measured: 4e-10 (the plain weave at 1 % weft);
# its shear slope is zero by symmetry, ~1e-6 J/m² of round-off (the energy's 1e-13 over the
# 1e-7 step), against slopes of ~500 J/m² along the axes.
FLAT_SLOPE_RTOL = 1e-6
# The search's Ū against the least Ū Nelder–Mead finds over the same three strains: the search
# stops when the decrease its slopes promise is below 1e-3 of Ū (SEARCH_ENERGY_RTOL), and
# Nelder–Mead's simplex ends within its own fatol. Measured on the plain weave at 312 /m: 4.8e-6
# (weft bend, 13 solves against Nelder–Mead's 88) and 1.5e-6 (saddle, 12 against 95).
SEARCH_ENERGY_RTOL = 2e-3
# A bend path's Ū against each bend searched alone from I = Id: both stop within the searches'
# tolerance (SEARCH_ENERGY_RTOL, 1e-3 of Ū), from different starts. Measured on the plain weave:
# 1e-5 (8e-5 for its largest saddle); on a knit or the satin the two can land in different
# equilibria (the satin's bias bend at -175 /m: 1.9 %), which the weave does not have.
PATH_ENERGY_RTOL = 1e-3
OPTIONS = QuasiStaticOptions(max_iterations=MAX_ITERATIONS)


def linear_fiber(E: float) -> Fiber:
    return Fiber(name="linear", density_kg_m3=1000.0, young_min_pa=E, young_max_pa=E, breaking_strain=0.1,
                 poisson=0.3, friction=0.2, fineness_dtex=2.0, flexural_rigidity_nm2_per_tex2=0.5e-9,
                 torsional_rigidity_nm2_per_tex2=0.2e-9)


@functools.lru_cache(maxsize=None)
def two_layers(r=1e-4, d=3e-4, E=2e9):
    """Two straight weft yarns of a linear fibre per repeat (2 mm × 2d), one 4r above the other, not
    touching; the upper one has twice the nodes, so the tiling's reference surface (the nodes' mean
    height) lies 8r/3 above the lower yarn, not midway (2r) where their stretch balances."""
    yarns = []
    for count, y, z in ((16, 0.5 * d, 0.0), (32, 1.5 * d, 4.0 * r)):
        x = np.linspace(0.0, 2e-3, count, endpoint=False)
        yarns.append((np.column_stack([x, np.full_like(x, y), np.full_like(x, z)]), (1, 0)))
    pattern = YarnPattern.from_yarns("layers", "woven", (2e-3, 2.0 * d), r, yarns)
    return relax_pattern(pattern, linear_fiber(E), shrink=1.0, yarn=YarnConstruction(model="solid"))


@functools.lru_cache(maxsize=None)
def plain_weave():
    return relax_for_fit(Fabric(name="plain", fiber=get_fiber("cotton"), structure="plain", areal_density=0.2,
                                counts=(2500.0, 2500.0)))


@pytest.mark.parametrize("curvature", [20.0, -20.0])
def test_a_bend_at_zero_membrane_force_is_taken_about_its_neutral_surface(curvature):
    # Each yarn follows the surface at its height h: bent about a surface at height z, Ū = Σ (EI +
    # EA (h − z)²) κ² / 2 over the repeat's area 2d per unit length. Held at the reference surface
    # (the paper's I = Id) that is (EI + 40/9 EA r²) κ² / 2d; about the neutral surface (midway,
    # 2r/3 below the reference) (EI + 4 EA r²) κ² / 2d, 10 % less: the search must find that surface
    # (the free strain along the curvature) and that energy, the other two strains being free
    # motions of the straight yarns (their spacing and the shear along them cost nothing).
    r, d = 1e-4, 3e-4
    relaxed = two_layers()
    heights = relaxed.state.node_position[:, 2]
    assert heights.mean() - heights.min() == pytest.approx(8.0 * r / 3.0, rel=1e-6)
    assert fabric_reach(relaxed) == pytest.approx(8.0 * r / 3.0 + r, rel=1e-6)
    bending, stretch = relaxed.yarn.bending_rigidity_nm2, relaxed.yarn.tensile_rigidity_n
    rest = solve_sample(relaxed, free_rest_sample())
    assert rest.converged
    sample = solve_sample(relaxed, SampleSpec.at(Family.WEFT_BEND, curvature))
    assert sample.converged
    assert np.array_equal(sample.I, np.eye(2))
    assert sample.energy_density - rest.energy_density == pytest.approx(
        (bending + 4.0 * stretch * r**2) * curvature**2 / (2 * d), rel=NEUTRAL_RTOL)
    # The reference surface lies 2r/3 from the neutral one: its strain along the curvature is
    # E00 = ±(2r/3) κ, stretched on the convex side.
    assert abs(sample.free_membrane_strain[0]) == pytest.approx(2.0 * r / 3.0 * abs(curvature), rel=OFFSET_RTOL)
    tiled, fixed, _ = _solve_with_continuation(relaxed, np.eye(2), sample.II, OPTIONS)
    assert fixed.converged
    assert fixed.energy.internal / tiled.area - rest.energy_density == pytest.approx(
        (bending + 40.0 / 9.0 * stretch * r**2) * curvature**2 / (2 * d), rel=NEUTRAL_RTOL)


def test_the_surface_slope_is_the_derivative_of_the_solved_energy():
    # The envelope theorem on a curved tiling: the slope of the balanced potential along a change of
    # the first form, the second held, equals the derivative of Ū through re-solved equilibria.
    relaxed = two_layers()
    II = np.diag([20.0, 0.0])
    form = membrane_form(np.array([1e-3, 0.0, 0.0]))
    tiled, result, _ = _solve_with_continuation(relaxed, form, II, OPTIONS)
    assert result.converged
    change, step = np.diag([1.0, 0.0]), 1e-5
    energies = []
    for sign in (1.0, -1.0):
        moved, solved = _solve_near(relaxed, form + 2.0 * sign * step * change, II, OPTIONS, (tiled, result))
        assert solved.converged
        energies.append(solved.energy.internal / moved.area)
    slope = _surface_green_slope(CarriedEquilibrium(relaxed, tiled, result.state, result.contacts.pairs), result, form,
                                 change)
    assert slope == pytest.approx((energies[0] - energies[1]) / (2.0 * step), rel=SURFACE_SLOPE_RTOL)


@pytest.mark.parametrize("change", [np.diag([1.0, 0.0]), np.diag([0.0, 1.0]), np.array([[0.0, 1.0], [1.0, 0.0]])])
def test_on_a_flat_tiling_the_surface_slope_is_the_flat_slope(change):
    relaxed = plain_weave()
    form = np.diag([1.01**2, 1.0])
    tiled, result, _ = _solve_with_continuation(relaxed, form, np.zeros((2, 2)), OPTIONS)
    assert result.converged and len(result.contacts.pairs) > 0
    flat = _green_slope(tiled.model, result, form, change, tiled.area)
    carried = CarriedEquilibrium(relaxed, tiled, result.state, result.contacts.pairs)
    assert _surface_green_slope(carried, result, form, change) == pytest.approx(
        flat, rel=FLAT_SLOPE_RTOL, abs=FLAT_SLOPE_RTOL * 1e3)


@pytest.mark.parametrize("family", [Family.WEFT_BEND, Family.SADDLE_BEND])
def test_the_bend_search_finds_the_least_energy_nelder_mead_finds(family):
    # An independent minimiser of the same function (Ū of the solved sample over the three membrane
    # strains), which uses no slopes: scipy's Nelder–Mead, each evaluation solved from the affine
    # start. The plain weave at the default range's largest curvature, where the paper's I = Id
    # and zero membrane force differ most.
    relaxed = plain_weave()
    II = SampleSpec.at(family, 0.25 / float(max(relaxed.repeat_size))).II
    search = _search_bend(relaxed, II, OPTIONS)
    assert search.failure is None
    found = search.result.energy.internal / search.tiled.area

    def energy(free):
        form = membrane_form(free)
        if np.linalg.det(form) <= 0.0:
            return math.inf
        tiled, result, _ = _solve_with_continuation(relaxed, form, II, OPTIONS)
        return result.energy.internal / tiled.area if result is not None and result.converged else math.inf

    fixed = energy(np.zeros(3))
    scale = float(np.abs(np.linalg.eigvalsh(II)).max()) * fabric_reach(relaxed)
    least = scipy.optimize.minimize(energy, np.zeros(3), method="Nelder-Mead",
                                    options={"initial_simplex": np.vstack([np.zeros(3), 0.5 * scale * np.eye(3)]),
                                             "xatol": 1e-3 * scale, "fatol": 1e-5 * fixed, "maxfev": 300})
    assert found < fixed
    assert found == pytest.approx(least.fun, rel=SEARCH_ENERGY_RTOL)


def test_a_bend_result_carries_its_free_strain_and_reads_it_back():
    spec = SampleSpec.at(Family.WEFT_BEND, 10.0)
    result = SampleResult(spec, 1e-3, True, Residual(1e-9, 1e-9, 0.0, 0.0), free_membrane_strain=(1e-4, -2e-4, 0.0))
    back = SampleResult.from_dict(result.to_dict())
    assert back.free_membrane_strain == (1e-4, -2e-4, 0.0)
    assert all(math.isnan(e) for e in SampleResult.from_dict(
        {k: v for k, v in result.to_dict().items() if k != "free_membrane_strain"}).free_membrane_strain)
    with pytest.raises(ValueError, match="only defined for a bending family"):
        SampleResult(SampleSpec.at(Family.WEFT_STRETCH, 0.01), 1e-3, True, Residual(1e-9, 1e-9, 0.0, 0.0),
                     free_membrane_strain=(1e-4, 0.0, 0.0))
    with pytest.raises(ValueError, match="three Green strains"):
        SampleResult(spec, 1e-3, True, Residual(1e-9, 1e-9, 0.0, 0.0), free_membrane_strain=(1e-4, 0.0))


def test_bends_are_grouped_into_paths_of_growing_curvature():
    specs = sample_design(SampleRanges(stretch=0.1, curvature=100.0), 3)
    groups = sample_groups(specs)
    assert sorted(i for group in groups for i in group) == list(range(len(specs)))
    paths = [group for group in groups if len(group) > 1]
    # A path per bend family and sign; the unbent reference and every membrane sample alone.
    assert len(paths) == 8
    for path in paths:
        assert len({(specs[i].family, specs[i].parameter > 0) for i in path}) == 1
        assert not specs[path[0]].is_membrane
        assert [abs(specs[i].parameter) for i in path] == sorted(abs(specs[i].parameter) for i in path)
    assert (1,) in groups and specs[1].family == free_rest_sample().family and specs[1].parameter == 0.0
    # With friction the membrane samples go on load paths too (the undeformed one alone).
    loading = sample_groups(specs, friction=True)
    assert (0,) in loading
    assert all(len(group) > 1 or specs[group[0]].parameter == 0.0 for group in loading)
    with pytest.raises(ValueError, match="not one group"):
        solve_group(two_layers(), [specs[path[0]] for path in paths[:2]])


def test_a_bend_path_lands_where_each_bend_searched_alone_lands():
    # Each bend of a path starts from the gentler one's answer (its strains scaled, its Hessian):
    # the same least Ū as a search from I = Id, within the searches' own tolerance.
    relaxed = plain_weave()
    curvatures = magnitudes(0.25 / float(max(relaxed.repeat_size)), SMALLEST_CURVATURE, 4)
    specs = [SampleSpec.at(Family.WEFT_BEND, -k) for k in curvatures]
    path = solve_group(relaxed, specs)
    for along, spec in zip(path, specs):
        alone = solve_sample(relaxed, spec)
        assert along.converged and alone.converged
        assert along.energy_density == pytest.approx(alone.energy_density, rel=PATH_ENERGY_RTOL), spec
