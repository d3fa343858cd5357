"""Phase-1 relaxation of periodic repeats.

Every named structure and every HYLC file relaxes to a converged equilibrium without yarns
overlapping; the relaxed repeat carries the areal density the label states (recomputed here from
the relaxed centrelines); relaxed weaves keep their drafts; a square plain weave is symmetric
under swapping warp and weft; and relaxing a relaxed repeat changes nothing.
"""

import functools
from pathlib import Path

import numpy as np
import pytest

from yarnfit.fabric import Fabric, named_patterns
from yarnfit.fibers import Fiber, get_fiber
from yarnfit.patterns import DRAFTS
from yarnfit.engine import RodMaterial
from yarnfit.relax import OVERLAP_TOLERANCE, relax, relax_pattern, relaxed_energy
from yarnfit.yarn import Yarn, YarnConstruction

HYLC = Path(__file__).parent / "data" / "hylc"
# The acceptance bound on overlaps after relaxation: 1 % of the diameter. (The solver's own
# penetration tolerance is 1e-5 on its sampled constraints; between samples a crossing hides at
# most 0.2 %.)
MAX_OVERLAP = 0.01
assert OVERLAP_TOLERANCE <= MAX_OVERLAP
# The radius fixed point stops at 1e-3 relative change of r: the areal density (∝ r²) is then
# within ~2e-3; the acceptance asks for 0.5 %.
AREAL_DENSITY_RTOL = 0.005
# Warp and weft of a square plain weave differ only by the order of their yarns in the solve.
SYMMETRY_RTOL = 0.01
# Relaxing a relaxed repeat: the second solve starts at the first one's equilibrium with zero
# contact multipliers and must come back to it; the acceptance bound.
RERELAX_ENERGY_RTOL = 1e-6


# Areal density of the named structures relaxed here (kg/m²): knits 150 g/m², wovens 200 g/m², but
# the 8-harness satin at its 70 ends/cm 150 g/m²: at 200 g/m² its round fibre-assembly yarns
# (φ = 0.6) are 0.151 mm thick, more than the 0.143 mm between ends (check_packing refuses it).
AREAL_DENSITY = {"knit": 0.15, "woven": 0.2, "satin-8": 0.15}


@functools.lru_cache(maxsize=None)
def relaxed_named(structure: str, counts=None):
    family = named_patterns()[structure]
    fabric = Fabric(name=structure, fiber=get_fiber("cotton"), structure=structure,
                    areal_density=AREAL_DENSITY.get(structure, AREAL_DENSITY[family]), counts=counts)
    return relax(fabric)


@functools.lru_cache(maxsize=None)
def relaxed_file(name: str):
    return relax(Fabric(name=name, fiber=get_fiber("polyester"), pattern_file=str(HYLC / f"{name}.pyp")))


@pytest.mark.parametrize("structure", sorted(named_patterns()))
def test_every_named_structure_relaxes(structure):
    result = relaxed_named(structure)
    assert result.converged, result.residual
    assert result.penetration < MAX_OVERLAP and result.valid


@pytest.mark.parametrize("name", sorted(p.stem for p in HYLC.glob("*.pyp")))
def test_every_hylc_pattern_relaxes(name):
    result = relaxed_file(name)
    assert result.converged, result.residual
    assert result.penetration < MAX_OVERLAP and result.valid


def relaxed_centreline_length(result) -> np.ndarray:
    """Per yarn, the length of its relaxed centreline (edges into neighbouring tiles included)."""
    m, x = result.model, result.state.node_position
    vectors = x[m.edge_nodes[:, 1]] + m.edge_offset - x[m.edge_nodes[:, 0]]  # flat tiling: translations
    lengths = np.linalg.norm(vectors, axis=1)
    return np.array([lengths[m.rod_edges(r)].sum() for r in range(m.n_rods)])


@pytest.mark.parametrize("preset", ["cotton-jersey", "cotton-twill", "polyester-satin"])
def test_the_relaxed_repeat_carries_the_labels_areal_density(preset):
    fabric = Fabric.preset(preset)
    result = relax(fabric)
    assert result.converged
    length = relaxed_centreline_length(result).sum()
    px, py = result.repeat_size
    # Fibre mass per yarn length ρ φ π r² (the yarn packs its fibres at φ).
    phi = result.yarn.packing_fraction
    mass_per_area = fabric.fiber.density_kg_m3 * phi * np.pi * result.radius**2 * length / (px * py)
    assert mass_per_area == pytest.approx(fabric.areal_density, rel=AREAL_DENSITY_RTOL)


def height_at_crossing(points: np.ndarray, axis: int, coordinate: float, period: float) -> float:
    """Height of a yarn's relaxed centreline where it passes ``coordinate`` along ``axis``
    (linear interpolation between the two nodes around it, periodic)."""
    u = np.mod(points[:, axis] - coordinate + 0.5 * period, period) - 0.5 * period
    order = np.argsort(u)
    u, z = u[order], points[order, 2]
    return float(np.interp(0.0, u, z))


@pytest.mark.parametrize("structure", ["plain", "twill-2/1", "twill-2/2", "twill-3/1"])
def test_a_relaxed_weave_keeps_its_draft(structure):
    draft = DRAFTS[structure]
    n_picks, n_ends = draft.shape
    result = relaxed_named(structure)
    assert result.converged
    m, x = result.model, result.state.node_position
    px, py = result.repeat_size
    yarns = [x[m.rod_nodes(r)] for r in range(m.n_rods)]
    picks, ends = yarns[:n_picks], yarns[n_picks:]
    for i in range(n_picks):
        for j in range(n_ends):
            # The crossing sits where the end's mean x meets the pick's mean y.
            x_end, y_pick = ends[j][:, 0].mean(), picks[i][:, 1].mean()
            z_pick = height_at_crossing(picks[i], 0, x_end, px)
            z_end = height_at_crossing(ends[j], 1, y_pick, py)
            assert (z_end > z_pick) == bool(draft[i, j]), (structure, i, j, z_end, z_pick)


def test_a_square_plain_weave_is_symmetric_in_warp_and_weft():
    result = relaxed_named("plain", counts=(2500.0, 2500.0))
    assert result.converged
    per_yarn = relaxed_centreline_length(result)
    weft, warp = per_yarn[:2].sum(), per_yarn[2:].sum()
    area = float(np.prod(result.repeat_size))
    assert warp / area == pytest.approx(weft / area, rel=SYMMETRY_RTOL)


@pytest.mark.parametrize("structure", ["twill-2/1", "jersey"])
def test_relaxing_a_relaxed_repeat_changes_nothing(structure):
    first = relaxed_named(structure)
    again = relax_pattern(first.relaxed_pattern(), first.fiber, shrink=1.0)
    assert again.converged
    assert abs(again.energy.total - first.energy.total) <= RERELAX_ENERGY_RTOL * abs(first.energy.total)
    # Its rest state is the relaxed shape: zero internal energy there.
    assert abs(relaxed_energy(first).total) <= RERELAX_ENERGY_RTOL * abs(first.energy.total)


def test_the_solid_yarn_is_the_papers_rod():
    # The paper's yarn: a solid cylinder of E_min, ν, ρ whose modulus grows as E_min + k ε and
    # reaches E_max at the breaking strain, in tension and compression alike.
    fiber = get_fiber("wool")
    relaxed = relax(Fabric.preset("wool-jersey", yarn=YarnConstruction(model="solid")))
    slope = (fiber.young_max_pa - fiber.young_min_pa) / fiber.breaking_strain
    paper = RodMaterial(young_modulus=fiber.young_min_pa, poisson_ratio=fiber.poisson, density=fiber.density_kg_m3,
                        hardening_tension=slope, hardening_compression=slope).section(relaxed.radius)
    assert relaxed.yarn.section() == paper
    np.testing.assert_array_equal(relaxed.model.joint_stiffness[:, 0], paper.bending_rigidity[0])
    np.testing.assert_array_equal(relaxed.model.edge_stretch_stiffness, paper.tensile_rigidity)
    linear = Fiber(name="linear", density_kg_m3=1000.0, young_min_pa=2e9, young_max_pa=2e9,
                           breaking_strain=0.2, poisson=0.3, friction=0.2)
    assert Yarn.build(linear, YarnConstruction(model="solid"), 90e-6).section().hardening_tension == 0.0


def test_progress_reports_positions_in_yarn_order():
    fabric = Fabric(name="plain", fiber=get_fiber("cotton"), structure="plain", areal_density=0.2)
    pattern = fabric.pattern()
    seen = []
    relax_pattern(pattern, fabric.fiber, on_iteration=lambda p: seen.append(p.position.copy()))
    expected = np.concatenate([pattern.node_position[y.nodes] for y in pattern.yarns()])
    np.testing.assert_array_equal(seen[0], expected)


def test_a_relaxation_that_leaves_overlaps_is_not_valid():
    import dataclasses

    result = relaxed_named("plain")
    assert result.valid
    assert not dataclasses.replace(result, penetration=2 * OVERLAP_TOLERANCE).valid
    assert not dataclasses.replace(result, converged=False).valid
