"""Fibre database, fibre → rod material, lookup by name and user fibre files."""

import dataclasses
import json
import math

import pytest

from yarnfit.fibers import FIBERS, Fiber, UnknownFiberError, get_fiber, load_fiber_file

# k = (E_max − E_min)/ε_max is one subtraction and one division: a few ulps of E_max.
ROUND_OFF_REL = 1e-14
# The design notes quote handbook moduli to two significant figures ("~3.4 GPa", "7–13 GPa"), so
# a modulus converted from N/tex agrees with them to half a unit in the second figure (< 5 %).
DESIGN_NOTE_REL = 0.05

PAPER_FIBERS = {
    # name: (ρ kg/m³, E_min Pa, E_max Pa, ε_max), the paper's supplementary fibre table.
    "wool": (1310.0, 2.3e9, 3.4e9, 0.3),
    "cotton": (1520.0, 5.3e9, 6.2e9, 0.1),
    "polyester": (1380.0, 1.5e9, 10.6e9, 0.4),
}

HANDBOOK_FIBERS = {
    # name: (ρ kg/m³, E_min Pa, E_max Pa) as given in docs/design.md §4.
    "nylon": (1140.0, 3.4e9, 3.4e9),
    "silk": (1340.0, 9.8e9, 9.8e9),
    "viscose": (1490.0, 7e9, 13e9),
    "linen": (1500.0, 27e9, 27e9),
    "acrylic": (1190.0, 7.4e9, 7.4e9),
}

VALID = {
    "name": "hemp",
    "density_kg_m3": 1480.0,
    "young_min_pa": 3.2e10,
    "young_max_pa": 3.5e10,
    "breaking_strain": 0.022,
    "poisson": 0.36,
    "friction": 0.3,
}


def write_json(tmp_path, data, name="fibre.json"):
    path = tmp_path / name
    path.write_text(data if isinstance(data, str) else json.dumps(data), encoding="utf-8")
    return path


def test_paper_fibres_have_the_papers_numbers_exactly():
    for name, (density, e_min, e_max, strain) in PAPER_FIBERS.items():
        fiber = FIBERS[name]
        assert (fiber.density_kg_m3, fiber.young_min_pa, fiber.young_max_pa, fiber.breaking_strain) == (
            density,
            e_min,
            e_max,
            strain,
        )
        assert "Serra et al. 2019" in fiber.source
    # Poisson's ratios from the paper's own notes.
    assert FIBERS["polyester"].poisson == 0.25
    assert FIBERS["cotton"].poisson == 0.36


def test_handbook_fibres_match_the_design_notes():
    for name, (density, e_min, e_max) in HANDBOOK_FIBERS.items():
        fiber = FIBERS[name]
        assert fiber.density_kg_m3 == density
        assert fiber.young_min_pa == pytest.approx(e_min, rel=DESIGN_NOTE_REL)
        assert fiber.young_max_pa == pytest.approx(e_max, rel=DESIGN_NOTE_REL)


def test_database_has_required_fibres_keyed_by_their_names():
    assert set(PAPER_FIBERS) | set(HANDBOOK_FIBERS) <= set(FIBERS)
    for key, fiber in FIBERS.items():
        assert key == fiber.name == key.lower()
        assert fiber.source


@pytest.mark.parametrize("name", sorted(FIBERS))
def test_builtin_fibre_has_the_papers_hardening(name):
    fiber = FIBERS[name]
    # Re-validates every field (a frozen dataclass is only checked at construction).
    assert dataclasses.replace(fiber) == fiber

    # Reference: k = (E_max − E_min)/ε_max, the tangent modulus E_min + k ε reaching E_max at ε_max.
    k = (fiber.young_max_pa - fiber.young_min_pa) / fiber.breaking_strain
    assert math.isclose(fiber.hardening_pa, k, rel_tol=ROUND_OFF_REL)
    assert math.isclose(fiber.young_min_pa + fiber.hardening_pa * fiber.breaking_strain, fiber.young_max_pa, rel_tol=ROUND_OFF_REL)



def test_linear_fibre_has_no_hardening():
    fiber = Fiber(**{**VALID, "young_max_pa": VALID["young_min_pa"]})
    assert fiber.hardening_pa == 0.0
    assert FIBERS["linen"].hardening_pa == 0.0


def test_describe_is_one_line_with_units():
    for fiber in FIBERS.values():
        line = fiber.describe()
        assert "\n" not in line
        assert line.startswith(fiber.name)
        assert "kg/m³" in line and "GPa" in line and "ε_max" in line
    assert "5.3–6.2 GPa" in FIBERS["cotton"].describe()
    assert "E 27.0 GPa" in FIBERS["linen"].describe()


@pytest.mark.parametrize(
    "field, value, phrase",
    [
        ("name", "  ", "name"),
        ("density_kg_m3", -1.0, "density_kg_m3"),
        ("density_kg_m3", 0.0, "density_kg_m3"),
        ("young_min_pa", 0.0, "young_min_pa"),
        ("young_min_pa", 4e10, "must not exceed young_max_pa"),
        ("young_max_pa", float("inf"), "young_max_pa must be finite"),
        ("breaking_strain", 0.0, "breaking_strain"),
        ("breaking_strain", 30.0, "not a percentage"),
        ("poisson", 0.5, "poisson"),
        ("poisson", -1.0, "poisson"),
        ("friction", -0.1, "friction"),
        ("friction", 2.5, "friction"),
        ("friction", float("nan"), "friction must be finite"),
        ("density_kg_m3", "1480", "density_kg_m3 must be a real number"),
        ("poisson", True, "poisson must be a real number"),
    ],
)
def test_invalid_fields_are_rejected_with_name_and_value(field, value, phrase):
    with pytest.raises(ValueError, match=phrase) as info:
        Fiber(**{**VALID, field: value})
    assert repr(value) in str(info.value)


def test_get_fiber_ignores_case():
    assert get_fiber("Cotton") is FIBERS["cotton"]
    assert get_fiber("POLYESTER") is FIBERS["polyester"]
    assert get_fiber(" wool ") is FIBERS["wool"]


def test_unknown_fibre_lists_all_names_on_one_line():
    with pytest.raises(UnknownFiberError) as info:
        get_fiber("kevlar")
    message = str(info.value)
    assert isinstance(info.value, ValueError)
    assert "\n" not in message
    assert message.startswith("unknown fibre 'kevlar'; known fibres: ")
    assert message.endswith(", ".join(sorted(FIBERS)))


def test_fibre_file_round_trip(tmp_path):
    for fiber in (get_fiber("cotton"), get_fiber("nylon")):
        path = write_json(tmp_path, dataclasses.asdict(fiber), f"{fiber.name}.json")
        assert load_fiber_file(path) == fiber
        assert load_fiber_file(str(path)) == fiber


def test_fibre_file_without_source_is_linear_when_moduli_agree(tmp_path):
    path = write_json(tmp_path, {**VALID, "young_max_pa": VALID["young_min_pa"]})
    fiber = load_fiber_file(path)
    assert fiber.hardening_pa == 0.0
    assert str(path) in fiber.source


@pytest.mark.parametrize(
    "data, phrase",
    [
        ({k: v for k, v in VALID.items() if k != "friction"}, "missing keys: friction"),
        ({**VALID, "colour": "blue"}, "unknown keys: colour"),
        ({**VALID, "young_min_pa": 4e10}, "young_min_pa (40000000000.0) must not exceed young_max_pa"),
        ({**VALID, "density_kg_m3": -1480}, "density_kg_m3 must be > 0, got -1480.0"),
        ({**VALID, "breaking_strain": 0}, "breaking_strain must lie in (0, 1.5]"),
        ({**VALID, "poisson": "0.3"}, "non-numeric values: poisson='0.3'"),
        ([VALID], "expected a JSON object"),
        # The second comma of line 2 is its 24th character.
        ('{"name": "hemp",\n "density_kg_m3": 1480,,}', "invalid JSON at line 2, column 24"),
    ],
)
def test_bad_fibre_file_gives_one_line_message_naming_the_file(tmp_path, data, phrase):
    path = write_json(tmp_path, data)
    with pytest.raises(ValueError) as info:
        load_fiber_file(path)
    message = str(info.value)
    assert message.startswith(f"{path}: ")
    assert phrase in message
    assert "\n" not in message


def test_misspelt_key_reports_missing_and_unknown_together(tmp_path):
    data = {k: v for k, v in VALID.items() if k != "friction"} | {"frction": 0.3}
    with pytest.raises(ValueError, match="missing keys: friction; unknown keys: frction"):
        load_fiber_file(write_json(tmp_path, data))


def test_missing_fibre_file(tmp_path):
    path = tmp_path / "absent.json"
    with pytest.raises(ValueError, match="no such fibre file") as info:
        load_fiber_file(path)
    assert str(path) in str(info.value)


def test_unreadable_fibre_file(tmp_path):
    with pytest.raises(ValueError, match="cannot read fibre file"):
        load_fiber_file(tmp_path)  # a directory
