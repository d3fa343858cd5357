"""Figures and tables for textile users (yarnfit.plots): the files are written, the numbers they
plot are the sources' (the material file's samples and fit, the shell's laws, the validation
summary, a measured curve) in the stated units, and bad input fails in one line.

The material is fitted in memory to exact energies of a stiffening woven (tests/test_fit_nonlinear.py's
samples, with a rest energy and a residual stress), never by a yarn-level fit; the validation summary
is built from the suite's own result types."""

from __future__ import annotations

import csv
import functools
import json
import math

import numpy as np
import pytest

import yarnfit
from fabric_shell import FABRIC, H
from test_fit_nonlinear import LEVELS, RANGES, REST_ENERGY, RESIDUAL, samples_of
from yarnfit.engine import Residual
from yarnfit.fit import fit_shell
from yarnfit.material_file import MaterialFile
from yarnfit.plots import N_PER_M_IN_N_PER_CM, PERCENT, energy_scale, fit_figures, validation_figures
from yarnfit.samples import FAMILIES, SampleResult, SampleSpec, family_deformation, sample_design
from yarnfit.shell import GF_CM2_PER_CM, membrane_strain
from yarnfit.validate import DIRECTIONS, PULL_DIRECTIONS

# The textile units from their definitions, independently of yarnfit's constants:
# 1 N/cm = 1 N / 1e-2 m = 100 N/m, so N/m × 0.01 = N/cm;
N_PER_CM_PER_N_PER_M = 0.01
# 1 gf = 1e-3 kg × 9.80665 m/s² (standard gravity, exact by definition) = 9.80665e-3 N, and
# 1 gf·cm²/cm = 1 gf·cm = 9.80665e-3 N × 1e-2 m = 9.80665e-5 N·m, so
# N·m × 1/(1e-3 · 9.80665 · 1e-2) = N·m × 10197.16… = gf·cm²/cm.
GRAM_FORCE_N = 1e-3 * 9.80665
GF_CM2_PER_CM_PER_N_M = 1.0 / (GRAM_FORCE_N * 1e-2)
# The tables write floats with repr, so a number copied from a source reads back exactly; one
# converted by a factor differs from the same conversion done here by a rounding or two.
CONVERSION_RTOL = 1e-14
# The fitted shell recovers the exact material, a StVK one the ridges represent exactly, to the
# fit's tolerance (test_fit_nonlinear's RECOVERY_REL; its residual stress to 1e-6): the plotted
# shell part of a sample against the true material's energy.
RECOVERY_RTOL = 2e-5
# The fit's own prediction at a sample (the file's fitted_energy_density_j_per_m2) against the
# plotted shell curve plus the rest state: the same arithmetic in another order, round-off only.
PREDICTION_RTOL = 1e-10

FABRIC_NAME = "test twill"
TRUE = FABRIC
MEMBRANE_RESIDUAL = {k: v for k, v in RESIDUAL.items() if k.startswith("n")}


@functools.lru_cache(maxsize=None)
def material_data() -> str:
    """A material file's contents (as JSON text: every test decodes its own copy): the fit of the
    exact samples of a woven's design (both biases), plus two samples that did not converge, one
    with an energy and one without."""
    samples = samples_of(TRUE, REST_ENERGY, MEMBRANE_RESIDUAL,  # TRUE: FABRIC, below
                         specs=sample_design(RANGES, LEVELS, both_biases=True))
    samples.append(SampleResult(SampleSpec.at("weft_stretch", 0.15), 5.0, False, Residual(0.1, 0.1, 0.0, 0.0)))
    samples.append(SampleResult(SampleSpec.at("weft_stretch", 0.18), math.nan, False,
                                Residual(math.nan, math.nan, math.nan, math.nan)))
    fit = fit_shell(samples, H, residual_stress=True)
    # The keys MaterialFile.from_fit writes that the figures read (the yarn and relaxed repeat are
    # not needed).
    return json.dumps({
        "yarnfit_version": yarnfit.__version__,
        "inputs": {"fabric": FABRIC_NAME, "areal_density_kg_m2": 0.2},
        "shell": fit.material.to_dict(),
        "engineering": fit.material.engineering(),
        "fit": {**fit.quality_dict(), "stretch_range": RANGES.stretch, "curvature_range_per_m": RANGES.curvature},
        "samples": [s.to_dict() for s in samples],
    }, allow_nan=False)


def material_file(tmp_path):
    path = tmp_path / "twill.json"
    path.write_text(material_data())
    return path


def read_table(path) -> tuple[list[str], list[dict]]:
    with open(path, newline="", encoding="utf-8") as f:
        rows = list(csv.reader(f))
    header = rows[0]
    assert all(len(row) == len(header) for row in rows[1:]), path
    return header, [dict(zip(header, row)) for row in rows[1:]]


def cell(value: str) -> float:
    return math.nan if value == "" else float(value)


def assert_figures(paths, stem):
    png, svg = stem.with_name(stem.name + ".png"), stem.with_name(stem.name + ".svg")
    assert png in paths and svg in paths
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000
    text = svg.read_text()
    assert "<svg" in text and text.rstrip().endswith("</svg>")


# -- fit_figures ------------------------------------------------------------------------------


def test_fit_figures_writes_every_family_the_tension_and_the_bending(tmp_path):
    paths = fit_figures(material_file(tmp_path), tmp_path / "new" / "figures")
    folder = tmp_path / "new" / "figures"
    stem = "test_twill"  # the name made safe for a file name
    for family in FAMILIES:
        assert_figures(paths, folder / f"{stem}-fit-{family}")
        assert folder / f"{stem}-fit-{family}.csv" in paths
    for figure in ("tension", "bending"):
        assert_figures(paths, folder / f"{stem}-{figure}")
    csvs = [p for p in paths if p.suffix == ".csv"]
    assert folder / f"{stem}-bending-rigidity.csv" in csvs
    assert sorted(paths) == sorted(folder.iterdir())
    for path in csvs:
        header, rows = read_table(path)
        assert rows and all("[" in h for h in header if h not in ("series", "converged", "direction")), header


def test_the_plotted_samples_are_the_files_and_the_shell_curve_is_the_fits_prediction(tmp_path):
    file = MaterialFile.read(material_file(tmp_path))
    fit_figures(file, tmp_path)
    used = {(u["family"], u["parameter"]): u["fitted_energy_density_j_per_m2"] for u in file.data["fit"]["used"]}
    for family in ("weft_stretch", "shear", "weft_bend"):
        header, rows = read_table(tmp_path / f"test_twill-fit-{family}.csv")
        x = header[1]
        membrane = family in ("weft_stretch", "shear")
        assert x.endswith("[%]" if membrane else "[1/m]")
        scale = PERCENT if membrane else 1.0
        samples = [s for s in file.data["samples"] if s["family"] == family]
        plotted = [r for r in rows if r["series"].startswith("yarn level")]
        # Every sample of the file, in its order, its Ū as solved copied exactly.
        assert [cell(r[x]) for r in plotted] == [scale * s["parameter"] for s in samples]
        assert [cell(r["energy density as solved [J/m^2]"]) for r in plotted] == pytest.approx(
            [math.nan if s["energy_density_j_m2"] is None else s["energy_density_j_m2"] for s in samples],
            rel=0.0, abs=0.0, nan_ok=True)
        assert [r["converged"] == "true" for r in plotted] == [s["converged"] for s in samples]
        shell = {cell(r[x]): cell(r["energy density [J/m^2]"]) for r in rows if r["series"] == "shell"}
        for sample, row in zip(samples, plotted):
            I, II = family_deformation(family, sample["parameter"])
            rest = REST_ENERGY + sum(MEMBRANE_RESIDUAL[f"n{k}"] * membrane_strain(I)[k] for k in range(3))
            if not sample["converged"]:
                continue
            # As the shell sees it: Ū less the rest energy and residual stress the data were made
            # with, i.e. the true material's energy.
            assert cell(row["energy density [J/m^2]"]) == pytest.approx(
                float(TRUE.energy_density(I, II)), rel=RECOVERY_RTOL, abs=1e-12)
            # The curve passes through every sample's parameter, where it plus the fitted rest state
            # is the fit's own prediction, written by the fit.
            fit_rest = file.rest_state()
            fitted_rest = fit_rest[0] + sum(fit_rest[1][f"n{k}"] * membrane_strain(I)[k] for k in range(3))
            assert shell[cell(row[x])] + fitted_rest == pytest.approx(used[(family, sample["parameter"])],
                                                                      rel=PREDICTION_RTOL)
            assert fitted_rest == pytest.approx(rest, rel=RECOVERY_RTOL, abs=1e-9)
    # The two samples that did not converge: the one with an energy is plotted, the other is listed
    # without one.
    _, rows = read_table(tmp_path / "test_twill-fit-weft_stretch.csv")
    left_out = [r for r in rows if r["series"] == "yarn level, not converged"]
    assert [(cell(r["lambda - 1 [%]"]), r["converged"]) for r in left_out] == [(15.0, "false"), (18.0, "false")]
    assert cell(left_out[0]["energy density as solved [J/m^2]"]) == 5.0
    assert left_out[1]["energy density [J/m^2]"] == "" and left_out[1]["energy density as solved [J/m^2]"] == ""


def test_a_sample_left_out_does_not_set_the_energy_scale():
    # A jammed sample's solve stopped at 2e6 J/m² beside fitted samples of a few J/m²: the axis
    # spans the fitted ones and the shell's curve, 5 % either side.
    assert energy_scale(np.array([0.0, 1.0, 3.0, np.nan])) == pytest.approx((-0.15, 3.15))
    assert energy_scale(np.array([2.0])) == pytest.approx((1.9, 2.1))
    assert energy_scale(np.array([np.nan])) is None


def test_tension_table_is_the_shells_uniaxial_law_in_n_per_cm(tmp_path):
    file = MaterialFile.read(material_file(tmp_path))
    shell = file.shell
    fit_figures(file, tmp_path)
    _, rows = read_table(tmp_path / "test_twill-tension.csv")
    strain = np.array([cell(r["strain [%]"]) for r in rows]) / 100.0
    assert strain[0] == 0.0 and strain[-1] == pytest.approx(RANGES.stretch, rel=1e-15)  # the fitted range
    engineering = file.data["engineering"]
    for direction, degrees in PULL_DIRECTIONS.items():
        force = np.array([cell(r[f"{direction} force per width [N/cm]"]) for r in rows])
        law = np.array([cell(r[f"{direction} small-strain law [N/cm]"]) for r in rows])
        for k in (1, len(rows) // 2, len(rows) - 1):
            pulled = shell.uniaxial_pull(math.radians(degrees), 1.0 + strain[k]).force_n_per_m
            assert force[k] == pytest.approx(pulled * N_PER_CM_PER_N_PER_M, rel=1e-9)
        stiffness = shell.uniaxial_stiffness(math.radians(degrees))[0]
        np.testing.assert_allclose(law, stiffness * strain * N_PER_CM_PER_N_PER_M, rtol=1e-12)
        if "bias" not in direction:  # the engineering constants' free-width stiffnesses, as the file has them
            np.testing.assert_allclose(law, engineering[f"{direction}_stretch_n_per_m"] * strain
                                       * N_PER_CM_PER_N_PER_M, rtol=1e-12)
        # The stiffening membrane's force rises, above its small-strain law.
        assert np.all(np.diff(force) > 0.0) and np.all(force[1:] > law[1:])
    assert N_PER_M_IN_N_PER_CM == pytest.approx(1.0 / N_PER_CM_PER_N_PER_M, rel=CONVERSION_RTOL)


def test_bending_rigidities_are_the_engineering_constants_in_gf_cm2_per_cm(tmp_path):
    file = MaterialFile.read(material_file(tmp_path))
    fit_figures(file, tmp_path)
    engineering = file.data["engineering"]
    _, rows = read_table(tmp_path / "test_twill-bending-rigidity.csv")
    assert [r["direction"] for r in rows] == ["weft", "warp", "bias"]
    rigidity = {}
    for row in rows:
        si = cell(row["bending rigidity [N*m]"])
        assert si == engineering[f"bending_{row['direction']}_nm"]
        rigidity[row["direction"]] = cell(row["bending rigidity [gf*cm^2/cm]"])
        assert rigidity[row["direction"]] == pytest.approx(si * GF_CM2_PER_CM_PER_N_M, rel=CONVERSION_RTOL)
    assert 1.0 / GF_CM2_PER_CM == pytest.approx(GF_CM2_PER_CM_PER_N_M, rel=CONVERSION_RTOL)
    # The moment per width (gf·cm/cm = gf) in newtons is B (N·m) times κ (1/m), κ in 1/cm × 100.
    _, rows = read_table(tmp_path / "test_twill-bending.csv")
    curvature_per_m = np.array([cell(r["curvature [1/cm]"]) for r in rows]) * 100.0
    assert curvature_per_m[-1] == pytest.approx(RANGES.curvature, rel=1e-15)
    for direction in ("weft", "warp", "bias"):
        moment_n = np.array([cell(r[f"{direction} moment per width [gf*cm/cm]"]) for r in rows]) * GRAM_FORCE_N
        np.testing.assert_allclose(moment_n, engineering[f"bending_{direction}_nm"] * curvature_per_m, rtol=1e-13)


def test_a_file_without_samples_or_an_unwritable_folder_fails_in_one_line(tmp_path):
    data = json.loads(material_data())
    for samples in (None, []):
        bad = {**data}
        bad.pop("samples") if samples is None else bad.update(samples=samples)
        path = tmp_path / "old.json"
        path.write_text(json.dumps(bad))
        with pytest.raises(ValueError, match=r"^.*old\.json: no yarn-level samples.*`yarnfit fit`\)$") as error:
            fit_figures(path, tmp_path / "out")
        assert "\n" not in str(error.value)
    assert not (tmp_path / "out").exists()  # nothing written for a file that cannot be drawn
    broken = {**data, "samples": [*data["samples"][:3], {"family": "weft_stretch", "parameter": 0.1}]}
    with pytest.raises(ValueError, match=r"^material: samples\[3\]: missing keys I, II, energy_density_j_m2, "
                                         r"converged$"):
        fit_figures(broken, tmp_path / "out")
    blocker = tmp_path / "a file"
    blocker.write_text("in the way")
    with pytest.raises(OSError, match=r"a file/figures: cannot create the figure directory \(") as error:
        fit_figures(data, blocker / "figures")
    assert "\n" not in str(error.value)


def test_samples_read_back_as_written(tmp_path):
    file = MaterialFile.read(material_file(tmp_path))
    samples = file.samples()
    assert [s.to_dict() for s in samples] == file.data["samples"]
    assert file.rest_state()[0] == pytest.approx(REST_ENERGY, rel=1e-12)


# -- validation_figures ---------------------------------------------------------------------------

REFERENCE_CSV = """# a made-up measurement, in the units a lab writes
direction,strain [%],force per width [N/cm],compression ratio [1]
weft,1,0.12,0.99
weft,4,0.60,
warp,2,0.20,0.98
"""


def validation_summary(shell) -> dict:
    """A `yarnfit validate` summary of the stretch and yarn scenes, built from their own result
    types (StripResult, StretchResult, YarnResult): strips that read 5 % above the shell's
    small-strain law, the last level of the weft strip not at rest; a yarn swatch in weft and warp
    with one solve that did not converge; a weft shell strip of the swatch's proportions."""
    from yarnfit.validate.stretch import STRAIN_LEVELS, StretchResult, StripResult
    from yarnfit.validate.swatch import YarnResult

    levels = np.array(STRAIN_LEVELS)
    strips = []
    for direction, degrees in DIRECTIONS.items():
        angle = math.radians(degrees)
        law = shell.uniaxial_stiffness(angle)[0]
        settled = np.ones(len(levels), bool)
        settled[-1] = direction != "weft"
        strips.append(StripResult(f"8x5_{direction}", 0.08, 0.05, angle, levels * 0.99, 1.05 * law * levels * 0.99,
                                  1.0 - 0.2 * levels, settled, 1.0, 1.1 * law, np.ones(len(levels), bool)))
    stretch = StretchResult(strips, shell).summary()
    strains = [0.0, 0.02, 0.05, 0.1]
    directions = {d: {"direction": d, "gauge_m": 0.012, "width_m": 0.008, "strain": strains,
                      "force_n_per_m": [1.2 * shell.uniaxial_stiffness(math.radians(DIRECTIONS[d]))[0] * e
                                        for e in strains],
                      "compression_ratio": [1.0, 0.99, 0.97, 0.95], "converged": d != "warp",
                      "points": [{"converged": not (d == "warp" and k == 3)} for k in range(4)]}
                  for d in ("weft", "warp")}
    # The weft swatch measured where it is uniform too (its middle half's pull at its middle's
    # strain); the warp's points, as an older run's, without.
    for k, point in enumerate(directions["weft"]["points"]):
        point.update(middle_force_n_per_m=1.5 * directions["weft"]["force_n_per_m"][k], mid_strain=1.2 * strains[k])
    yarn = YarnResult(name=FABRIC_NAME, strains=strains, directions=directions, seconds=1.0, material=FABRIC_NAME,
                      quick=True, relaxation={}, recording=None).summary()
    like_swatch = StripResult("swatch_weft", 0.08, 0.08 * 0.008 / 0.012, 0.0, levels,
                              1.1 * strips[0].force_per_width_n_per_m, 1.0 - 0.2 * levels, np.ones(len(levels), bool),
                              1.0, 1.0, np.ones(len(levels), bool))
    return {"yarnfit_version": yarnfit.__version__, "material": {"file": "twill.json", "name": FABRIC_NAME},
            "quick": True, "scenes": {"stretch": stretch, "yarn": yarn}, "wall_seconds": {},
            "shell_vs_yarn": {"shell_strips": {"swatch_weft": like_swatch.summary(shell)}}}


def test_validation_figures_plot_the_summarys_curves_in_n_per_cm(tmp_path):
    shell = MaterialFile.read(json.loads(material_data())).shell
    summary = validation_summary(shell)
    summary_path = tmp_path / "summary.json"
    summary_path.write_text(json.dumps(summary))
    reference = tmp_path / "lab.csv"
    reference.write_text(REFERENCE_CSV)
    paths = validation_figures(summary_path, tmp_path / "figures", reference)
    for direction in DIRECTIONS:
        assert_figures(paths, tmp_path / "figures" / f"test_twill-stretch-{direction}")
    assert len(paths) == 9
    strips = summary["scenes"]["stretch"]["strips"]
    for direction in DIRECTIONS:
        header, rows = read_table(tmp_path / "figures" / f"test_twill-stretch-{direction}.csv")
        assert header == ["series", "strain [%]", "force per width [N/cm]", "compression ratio [1]", "converged"]
        by_series = {}
        for row in rows:
            by_series.setdefault(row["series"], []).append(row)
        strip = strips[f"8x5_{direction}"]
        shell_rows = by_series["shell in MuJoCo, 8 x 5 cm strip"]
        np.testing.assert_allclose([cell(r["force per width [N/cm]"]) for r in shell_rows],
                                   np.array(strip["force_per_width_n_per_m"]) * N_PER_CM_PER_N_PER_M,
                                   rtol=CONVERSION_RTOL)
        np.testing.assert_allclose([cell(r["strain [%]"]) for r in shell_rows], np.array(strip["strain"]) * 100.0,
                                   rtol=CONVERSION_RTOL)
        assert [r["converged"] for r in shell_rows][-1] == ("false" if direction == "weft" else "true")
        # Without the material the law is the summary's small-strain one.
        law = by_series["shell law at small strain, width free"]
        x = np.array([cell(r["strain [%]"]) for r in law]) / 100.0
        np.testing.assert_allclose([cell(r["force per width [N/cm]"]) for r in law],
                                   strip["uniaxial_law_n_per_m"] * x * N_PER_CM_PER_N_PER_M, rtol=1e-12)
        yarn = summary["scenes"]["yarn"]["directions"].get(direction)
        yarn_rows = by_series.get("yarn level, 1.2 x 0.8 cm swatch", [])
        if yarn is None:
            assert not yarn_rows
        else:
            np.testing.assert_allclose([cell(r["force per width [N/cm]"]) for r in yarn_rows],
                                       np.array(yarn["force_n_per_m"]) * N_PER_CM_PER_N_PER_M, rtol=CONVERSION_RTOL)
            assert [r["converged"] == "true" for r in yarn_rows] == [p["converged"] for p in yarn["points"]]
        middle_rows = by_series.get("yarn level, middle half at its own strain", [])
        if direction == "weft":
            np.testing.assert_allclose([cell(r["force per width [N/cm]"]) for r in middle_rows],
                                       [p["middle_force_n_per_m"] * N_PER_CM_PER_N_PER_M for p in yarn["points"]],
                                       rtol=CONVERSION_RTOL)
            np.testing.assert_allclose([cell(r["strain [%]"]) for r in middle_rows],
                                       [100.0 * p["mid_strain"] for p in yarn["points"]], rtol=CONVERSION_RTOL)
        else:
            assert not middle_rows
    # The measured curve in the lab's own units, read back as written; the shell strip of the
    # swatch's proportions beside the others.
    _, rows = read_table(tmp_path / "figures" / "test_twill-stretch-weft.csv")
    like = [r for r in rows if r["series"] == "shell in MuJoCo, 8 x 5.33 cm strip (the swatch's proportions)"]
    like_swatch = summary["shell_vs_yarn"]["shell_strips"]["swatch_weft"]
    np.testing.assert_allclose([cell(r["force per width [N/cm]"]) for r in like],
                               np.array(like_swatch["force_per_width_n_per_m"]) * N_PER_CM_PER_N_PER_M,
                               rtol=CONVERSION_RTOL)
    measured = [(cell(r["strain [%]"]), cell(r["force per width [N/cm]"]), cell(r["compression ratio [1]"]))
                for r in rows if r["series"] == "measured: lab"]
    np.testing.assert_allclose(measured, [(1.0, 0.12, 0.99), (4.0, 0.60, math.nan)], rtol=CONVERSION_RTOL)  # NaN = NaN


def test_with_the_material_the_law_is_the_shells_uniaxial_tension(tmp_path):
    file = MaterialFile.read(json.loads(material_data()))
    validation_figures(validation_summary(file.shell), tmp_path, material=file)
    _, rows = read_table(tmp_path / "test_twill-stretch-bias.csv")
    law = [r for r in rows if r["series"] == "shell law, width free"]
    assert law
    for row in law[1::25]:
        strain = cell(row["strain [%]"]) / 100.0
        pulled = file.shell.uniaxial_pull(math.radians(DIRECTIONS["bias"]), 1.0 + strain).force_n_per_m
        assert cell(row["force per width [N/cm]"]) == pytest.approx(pulled * N_PER_CM_PER_N_PER_M, rel=1e-9)


def test_a_summary_without_stretch_curves_fails_in_one_line(tmp_path):
    summary = {"material": {"name": FABRIC_NAME}, "scenes": {"sphere": {"settled": True}}}
    with pytest.raises(ValueError, match=r"^summary: no stretch curves \(run `yarnfit validate` with the scenes "
                                         r"stretch or yarn\)$"):
        validation_figures(summary, tmp_path / "out")
    assert not (tmp_path / "out").exists()
    with pytest.raises(ValueError, match=r"missing\.json: no such validation summary$"):
        validation_figures(tmp_path / "missing.json", tmp_path / "out")
    with pytest.raises(ValueError, match=r"^summary: not a `yarnfit validate` summary"):
        validation_figures({"material": {}}, tmp_path / "out")
    broken = {"scenes": {"stretch": {"strips": {"8x5_weft": {"strain": [0.01]}}}}}
    with pytest.raises(ValueError, match=r"^summary: a stretch curve is malformed \(KeyError: "
                                         r"'force_per_width_n_per_m'\)$"):
        validation_figures(broken, tmp_path / "out")
