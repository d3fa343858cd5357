"""Fabric descriptions: presets, the paper's radius formula, default counts, packing limits and how
a ``.pyp`` file is used."""

import math
from pathlib import Path

import numpy as np
import pytest

from yarnfit.fabric import (
    DEFAULT_COUNTS_PER_CM,
    PRESETS,
    SHRINK,
    Fabric,
    named_patterns,
    radius_from_areal_density,
)
from yarnfit.fibers import get_fiber
from yarnfit.patterns import read_pyp
from yarnfit.yarn import SPINNING_DEFAULTS, YarnConstruction

HYLC = Path(__file__).parent / "data" / "hylc"
# The radius is a fixed point of the formula over the geometry, iterated to 1e-6 relative.
RADIUS_RTOL = 1e-5


def test_the_papers_five_fabrics_are_presets():
    assert set(PRESETS) == {"cotton-jersey", "wool-jersey", "polyester-jersey", "polyester-satin", "cotton-twill"}


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_preset_radius_solves_the_papers_formula(name):
    fabric = Fabric.preset(name)
    pattern = fabric.pattern()
    # r = sqrt(ρ_fabric p_x p_y / (ρ_yarn L0 π)), L0 the yarn length of the generated repeat and
    # ρ_yarn = φ ρ_fibre the density of the yarn (fibres packed at φ).
    px, py = pattern.repeat_size
    yarn_density = fabric.yarn.packing_fraction_for(fabric.fiber) * fabric.fiber.density_kg_m3
    expected = math.sqrt(fabric.areal_density * px * py / (yarn_density * pattern.yarn_length() * math.pi))
    assert pattern.radius == pytest.approx(expected, rel=RADIUS_RTOL)
    assert 10e-6 < pattern.radius < 500e-6  # a real yarn: tens to hundreds of micrometres


def test_radius_formula():
    # 200 g/m² of cotton (1520 kg/m³), 1 mm × 2 mm repeat holding 10 mm of yarn.
    r = radius_from_areal_density(0.2, 1520.0, (1e-3, 2e-3), 1e-2)
    assert math.pi * r**2 * 1e-2 * 1520.0 / (1e-3 * 2e-3) == pytest.approx(0.2, rel=1e-14)


def test_counts_default_to_the_structures_typical_ones():
    fabric = Fabric(name="t", fiber=get_fiber("cotton"), structure="twill-2/2", areal_density=0.2)
    ends, picks = DEFAULT_COUNTS_PER_CM["twill-2/2"]
    np.testing.assert_allclose(fabric.pattern().repeat_size, [4 / (ends * 100.0), 4 / (picks * 100.0)])


def test_every_named_structure_has_typical_counts():
    assert set(DEFAULT_COUNTS_PER_CM) == set(named_patterns())


@pytest.mark.parametrize("kwargs, message", [
    ({"structure": "tartan", "areal_density": 0.2}, "unknown pattern 'tartan'; known patterns: basket-2x2"),
    ({"structure": "plain", "areal_density": 0.0}, "areal density must be positive"),
    ({"structure": "plain", "areal_density": -0.1}, "areal density must be positive"),
    ({"structure": "plain"}, "needs an areal density"),
    ({"structure": "plain", "areal_density": 0.2, "counts": (3000.0, -1.0)}, "counts must be two positive"),
    ({"structure": "plain", "areal_density": 0.2, "pattern_file": "x.pyp"}, "not both"),
])
def test_bad_fabric_descriptions_are_named(kwargs, message):
    with pytest.raises(ValueError, match=message.replace("(", r"\(")):
        Fabric(name="t", fiber=get_fiber("cotton"), **kwargs)


def test_counts_that_pack_yarns_too_densely_are_rejected():
    # 400 g/m² of cotton at 80 × 80 threads/cm: yarns ~60 µm thick on a 125 µm pitch cannot cross.
    fabric = Fabric(name="t", fiber=get_fiber("cotton"), structure="plain", areal_density=0.4, counts=(8000.0, 8000.0))
    with pytest.raises(ValueError, match="cannot"):
        fabric.pattern()


def test_knit_counts_that_overlap_are_rejected():
    fabric = Fabric(name="t", fiber=get_fiber("wool"), structure="jersey", areal_density=0.6, counts=(4000.0, 4000.0))
    with pytest.raises(ValueError, match="overlap|cannot"):
        fabric.pattern()


def test_a_pyp_file_without_label_numbers_is_used_as_written():
    fabric = Fabric(name="t", fiber=get_fiber("polyester"), pattern_file=str(HYLC / "stockinette.pyp"))
    written = read_pyp(HYLC / "stockinette.pyp")
    pattern = fabric.pattern()
    assert pattern.radius == written.radius
    np.testing.assert_array_equal(pattern.repeat_size, written.repeat_size)
    np.testing.assert_array_equal(pattern.rest_length, written.rest_length)
    assert fabric.shrink == 1.0


@pytest.mark.parametrize("model", ["solid", "fibre-assembly"])
def test_the_yarn_density_is_the_packed_fibres(model):
    # The solid rod is a cylinder of fibre (φ = 1); a fibre assembly packs φ < 1 of fibre.
    fabric = Fabric.preset("cotton-twill", yarn=YarnConstruction(model=model))
    phi = 1.0 if model == "solid" else SPINNING_DEFAULTS["ring-spun"].packing_fraction
    assert fabric.yarn_density == phi * fabric.fiber.density_kg_m3


def test_a_pyp_file_with_an_areal_density_is_resized_and_shrunk():
    fabric = Fabric(name="t", fiber=get_fiber("polyester"), pattern_file=str(HYLC / "stockinette.pyp"),
                    areal_density=0.15, counts=(1800.0, 1300.0))
    pattern = fabric.pattern()
    assert fabric.shrink == SHRINK["knit"]
    # Two courses and two wales per repeat in that file.
    np.testing.assert_allclose(pattern.repeat_size, [2 / 1300.0, 2 / 1800.0])
    px, py = pattern.repeat_size
    yarn_density = fabric.yarn.packing_fraction_for(fabric.fiber) * fabric.fiber.density_kg_m3
    expected = math.sqrt(0.15 * px * py / (yarn_density * pattern.yarn_length() * math.pi))
    assert pattern.radius == pytest.approx(expected, rel=RADIUS_RTOL)


@pytest.mark.parametrize("structure, family", [("plain", "woven"), ("jersey", "knit")])
def test_shrink_factor_by_family(structure, family):
    fabric = Fabric(name="t", fiber=get_fiber("cotton"), structure=structure, areal_density=0.15)
    assert fabric.shrink == SHRINK[family] == {"woven": 0.9, "knit": 0.8}[family]
