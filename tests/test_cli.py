"""The ``yarnfit`` console script: listings, one-line errors for bad input, and a relaxation that
prints its summary and writes the recording the README documents."""

import json
import math
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import rerun as rr

import yarnfit
from yarnfit.patterns import read_pyp
from yarnfit.samples import design_size
from yarnfit.validate import PULL_DIRECTIONS


def run(*args: str) -> subprocess.CompletedProcess:
    # The script installed next to this interpreter by `pip install -e .`.
    script = Path(sys.executable).parent / "yarnfit"
    return subprocess.run([str(script), *args], capture_output=True, text=True, timeout=120)


def test_version():
    out = run("--version")
    assert out.returncode == 0
    assert out.stdout.strip() == f"yarnfit {yarnfit.__version__}"


def test_help():
    out = run("--help")
    assert out.returncode == 0
    assert "usage: yarnfit" in out.stdout
    assert "fabric" in out.stdout


# -- listings -------------------------------------------------------------------------------------


def test_materials_lists_fibres_and_presets_one_line_each():
    from yarnfit.fabric import PRESETS
    from yarnfit.fibers import FIBERS

    out = run("materials")
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    for name in list(FIBERS) + list(PRESETS):
        assert sum(line.split()[0] == name for line in lines if line.strip()) == 1, name


def test_patterns_lists_every_named_structure_one_line_each():
    from yarnfit.fabric import named_patterns

    out = run("patterns")
    assert out.returncode == 0, out.stderr
    first_words = [line.split()[0] for line in out.stdout.splitlines() if line.strip()]
    for name in named_patterns():
        assert first_words.count(name) == 1, name


# -- bad input: one line on stderr, exit status 2 -------------------------------------------------


def dangling_pyp(tmp_path) -> Path:
    """stocktiny.pyp with the edge leaving node 5 removed: node 5 is a dangling yarn end."""
    text = (Path(__file__).parent / "data" / "hylc" / "stocktiny.pyp").read_text().splitlines()
    edges = text.index("*E # edges: v0 v1 dx dy")
    kept = [line for k, line in enumerate(text) if not (k > edges and line.startswith("5 6 "))]
    assert len(kept) == len(text) - 1
    path = tmp_path / "dangling.pyp"
    path.write_text("\n".join(kept) + "\n")
    return path


BAD_INPUTS = {
    "unknown fibre": (["relax", "--fiber", "kevlarish", "--pattern", "plain", "--gsm", "150"],
                      ["kevlarish", "cotton", "wool", "polyester"]),
    "unknown pattern": (["relax", "--fiber", "cotton", "--pattern", "tartan", "--gsm", "150"],
                        ["tartan", "plain", "jersey", "satin-5"]),
    "unknown preset": (["relax", "linen-canvas"], ["linen-canvas", "cotton-jersey"]),
    "zero gsm": (["relax", "--fiber", "cotton", "--pattern", "plain", "--gsm", "0"], ["--gsm"]),
    "negative gsm": (["relax", "--fiber", "cotton", "--pattern", "plain", "--gsm", "-20"], ["--gsm"]),
    "overlapping counts": (["relax", "--fiber", "cotton", "--pattern", "plain", "--gsm", "400", "--counts", "80x80"],
                           ["80 ends/cm"]),
    "malformed counts": (["relax", "--fiber", "cotton", "--pattern", "plain", "--gsm", "150", "--counts", "30"],
                         ["--counts"]),
}


@pytest.mark.parametrize("case", sorted(BAD_INPUTS))
def test_bad_input_is_one_line_and_exit_status_2(case, tmp_path):
    args, mentions = BAD_INPUTS[case]
    out = run(*args, "--rerun", str(tmp_path / "x.rrd"))
    assert out.returncode == 2, (out.stdout, out.stderr)
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in out.stderr, out.stderr
    for word in mentions:
        assert word in lines[0], (word, lines[0])
    assert not (tmp_path / "x.rrd").exists()


def test_a_pyp_with_a_dangling_yarn_end_is_one_line_and_exit_status_2(tmp_path):
    out = run("relax", "--fiber", "polyester", "--pattern-file", str(dangling_pyp(tmp_path)))
    assert out.returncode == 2, (out.stdout, out.stderr)
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in out.stderr
    assert "dangling yarn end: vertex 5" in lines[0] and "dangling.pyp" in lines[0]


# -- a relaxation ---------------------------------------------------------------------------------


def readme_entity_paths(marker: str = "rerun-paths", root: str = "relax") -> set[str]:
    """Entity paths (``<family>`` templates kept) under ``root`` that the README documents between
    its ``<!-- marker:begin -->`` and ``<!-- marker:end -->`` comments."""
    readme = (Path(__file__).parents[1] / "README.md").read_text()
    section = readme.split(f"<!-- {marker}:begin -->")[1].split(f"<!-- {marker}:end -->")[0]
    return set(re.findall(rf"`({root}(?:/[\w<>]+)*)`", section))


def test_relax_prints_a_summary_and_writes_the_documented_recording(tmp_path):
    recording, output = tmp_path / "plain.rrd", tmp_path / "plain.pyp"
    out = run("relax", "--fiber", "cotton", "--pattern", "plain", "--gsm", "150", "--counts", "30x25",
              "--rerun", str(recording), "-o", str(output))
    assert out.returncode == 0, out.stderr
    for field in ("repeat", "yarn radius", "yarn per area", "residual", "worst overlap", "time", "converged"):
        assert field in out.stdout, field
    assert "converged         yes" in out.stdout

    documented = readme_entity_paths()
    assert {"relax/repeat/yarns", "relax/tiling/yarns", "relax/residual/force", "relax/energy/potential"} <= documented
    recorded = {chunk.entity_path.lstrip("/") for chunk in rr.chunk.RrdReader(recording).stream()}
    assert recorded - {"__properties"} == documented
    # Rerun's own tool (installed with rerun-sdk) reads the file back without error.
    rerun = Path(sys.executable).parent / "rerun"
    verify = subprocess.run([str(rerun), "rrd", "verify", str(recording)], capture_output=True, text=True, timeout=120)
    assert verify.returncode == 0, verify.stderr

    relaxed = read_pyp(output)
    assert relaxed.family == "woven" and len(relaxed.yarns()) == 4


# -- a shell fit ----------------------------------------------------------------------------------


# --samples for a fit in a test: the smallest design (one magnitude per family and sign).
SMALLEST_DESIGN = str(design_size(1))

FIT_BAD_INPUTS = {
    "too few samples": (["fit", "cotton-twill", "--samples", "5"], ["--samples", SMALLEST_DESIGN, "5"]),
    "unknown model": (["fit", "cotton-twill", "--model", "bogus"], ["--model", "bogus", "full", "paper"]),
    "no workers": (["fit", "cotton-twill", "--workers", "0"], ["--workers"]),
    "unknown fibre": (["fit", "--fiber", "kevlarish", "--pattern", "plain", "--gsm", "150"], ["kevlarish"]),
    "both frictions": (["fit", "cotton-twill", "--friction", "--frictionless"], ["--friction", "--frictionless"]),
}


@pytest.mark.parametrize("command", ["fit", "catalogue"])
def test_the_help_gives_the_sample_designs_bounds(command):
    # The parser does not import the fitting stack (a second of imports for every command), so
    # its help writes the bounds out: they must be the design's.
    from yarnfit.fabric_fit import DEFAULT_SAMPLES
    from yarnfit.samples import design_size

    out = run(command, "--help")
    assert (f"(at least {design_size(1)}; default {DEFAULT_SAMPLES}; a woven, pulled along both biases, "
            f"{design_size(1, both_biases=True) - design_size(1)} more)") in " ".join(out.stdout.split()), out.stdout


@pytest.mark.parametrize("case", sorted(FIT_BAD_INPUTS))
def test_fit_bad_input_is_one_line_and_exit_status_2(case, tmp_path):
    args, mentions = FIT_BAD_INPUTS[case]
    out = run(*args, "--rerun", str(tmp_path / "x.rrd"), "-o", str(tmp_path / "x.json"))
    assert out.returncode == 2, (out.stdout, out.stderr)
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in out.stderr, out.stderr
    for word in mentions:
        assert word in lines[0], (word, lines[0])
    assert not (tmp_path / "x.rrd").exists() and not (tmp_path / "x.json").exists()


def test_fit_prints_the_constants_and_writes_the_material_file_and_the_documented_recording(tmp_path):
    from yarnfit.material_file import MaterialFile
    from yarnfit.shell import GF_CM2_PER_CM

    recording, output = tmp_path / "plain-fit.rrd", tmp_path / "plain.json"
    out = subprocess.run([str(Path(sys.executable).parent / "yarnfit"), "fit", "--fiber", "cotton", "--pattern",
                          "plain", "--gsm", "200", "--samples", SMALLEST_DESIGN, "--workers", "2",
                          "--rerun", str(recording), "-o", str(output), "--figures", str(tmp_path / "figures")],
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    # Progress went to stderr: the relaxation, then samples done with the time left.
    assert "relaxed in" in out.stderr and re.search(r"samples (\d+)/\1: .* s left\]", out.stderr), out.stderr

    material = MaterialFile.read(output).shell
    engineering = material.engineering()
    summary = {line.split("  ")[1].strip(): line for line in out.stdout.splitlines() if line.startswith("  ")}
    for key, label in (("weft_stretch_n_per_m", "weft stretch"), ("shear_n_per_m", "shear")):
        value, unit = summary[label].split()[-2:]
        assert unit == "N/m" and float(value) == pytest.approx(engineering[key], rel=1e-4)
    # The material's own pulls along weft, warp and both biases at 2 and 5 %, width free.
    pulled = summary["pulled"]
    assert pulled.endswith("N/m at 2 / 5 % (width free)"), pulled
    for direction, degrees in PULL_DIRECTIONS.items():
        match = re.search(rf"{direction} \({degrees:g}°\) (\S+) / (\S+),? ", pulled)
        assert match, (direction, pulled)
        for text, strain in zip(match.groups(), (0.02, 0.05)):
            assert float(text.rstrip(",")) == pytest.approx(
                material.uniaxial_pull(math.radians(degrees), 1.0 + strain).force_n_per_m, rel=1e-3)
    # Bending in SI beside the textile unit (KES-F gf·cm²/cm).
    fields = summary["bending weft"].split()
    assert fields[-3:-1] == ["N·m", f"{engineering['bending_weft_nm'] / GF_CM2_PER_CM:.4g}"]
    assert fields[-1] == "gf·cm²/cm"
    assert "fit R²" in out.stdout and str(output) in out.stdout and str(recording) in out.stdout
    # The fit's figures and their tables (yarnfit.plots, tested in test_plots), where --figures says.
    assert {"plain-tension.png", "plain-tension.svg", "plain-tension.csv", "plain-bending.png"} <= \
        {p.name for p in (tmp_path / "figures").iterdir()}

    # The material file: stable keys, SI units, every sample, and a shell that reproduces them.
    data = json.loads(output.read_text())
    assert {"yarnfit_version", "inputs", "yarn", "shell", "engineering", "fit", "samples"} <= set(data)
    assert data["inputs"]["areal_density_kg_m2"] == pytest.approx(0.2)
    assert len(data["samples"]) == design_size(1, both_biases=True)  # and a woven's pulls along its other bias
    for sample in data["samples"]:
        assert {"family", "I", "II", "energy_density_j_m2", "residual", "converged"} <= set(sample)
    weft = [s for s in data["samples"] if s["family"] == "weft_stretch" and s["converged"] and s["parameter"] != 0.0]
    assert weft and all(material.energy_density(np.array(s["I"]), np.array(s["II"])) > 0 for s in weft)

    documented = readme_entity_paths("rerun-fit-paths", "fit")
    assert {"fit/sample/yarns", "fit/sample/energy", "fit/curves/<family>/shell"} <= documented
    recorded = {chunk.entity_path.lstrip("/") for chunk in rr.chunk.RrdReader(recording).stream()}
    recorded = {re.sub(r"^fit/curves/\w+/", "fit/curves/<family>/", p) for p in recorded - {"__properties"}}
    # `excluded` appears only when a sample did not converge.
    assert recorded - documented == set() and documented - recorded <= {"fit/curves/<family>/excluded"}
    rerun = Path(sys.executable).parent / "rerun"
    verify = subprocess.run([str(rerun), "rrd", "verify", str(recording)], capture_output=True, text=True, timeout=120)
    assert verify.returncode == 0, verify.stderr


def test_a_fit_prints_each_samples_energy_not_where_an_unconverged_solve_stopped_and_names_samples_taken_short():
    from dataclasses import replace

    from yarnfit.cli import sample_progress, short_sample_notes
    from yarnfit.engine import Residual
    from yarnfit.samples import Family, SampleResult, SampleSpec

    spec = SampleSpec.at(Family.WEFT_STRETCH, -0.1)
    stopped = replace(SampleResult.unsolved(spec, 600, 1.0), energy_density=2.35e6)  # a jam's stopped solve
    assert sample_progress(34, 93, stopped) == "samples 34/93: weft_stretch -0.1 → did not converge: excluded from the fit"
    solved = replace(stopped, converged=True, energy_density=2.98, residual=Residual(1e-11, 1e-12, 0.0, 0.0))
    assert sample_progress(35, 93, solved) == "samples 35/93: weft_stretch -0.1 → 2.98 J/m²"
    # A sample its path took short of the design (a jam) is fitted, and the summary says so.
    short = replace(solved, spec=SampleSpec.at(Family.WEFT_STRETCH, -0.07), design_parameter=-0.1)
    assert short_sample_notes([solved, short]) == [
        "weft_stretch sampled at -0.07 for the design's -0.1: its loading path converged no further "
        "(the fabric does not bear more)"]


def test_a_strict_fit_that_asks_for_an_indefinite_shell_fails_naming_the_family(tmp_path):
    # Cotton jersey's biaxial energies ask for s01 > √(s00 s11) (its loops trade course for wale
    # length; the paper's solid yarn, the smallest design): by default the coupling ends on the
    # positive-definite bound, with --strict the run fails naming the family of the first block found
    # indefinite. (Until session 43 polyester jersey's saddle bends asked for |b01| > √(b00 b11); solved
    # at zero membrane force they no longer do.) Frictionless: the paper's minimisers, whose
    # biaxial energies are the ones measured to ask for it (a knit is loaded with friction by default).
    recording, output = tmp_path / "x.rrd", tmp_path / "x.json"
    out = subprocess.run([str(Path(sys.executable).parent / "yarnfit"), "fit", "cotton-jersey", "--strict",
                          "--frictionless", "--yarn-model", "solid", "--figures", str(tmp_path / "figures"),
                          "--samples", SMALLEST_DESIGN, "--rerun", str(recording), "-o", str(output)],
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 1, (out.stdout, out.stderr)
    last = out.stderr.strip().splitlines()[-1]
    named = re.search(r"the (\w+) energies are inconsistent", last)
    assert last.startswith("yarnfit fit: failed:") and "Traceback" not in out.stderr, out.stderr
    assert named and named.group(1) in ("biaxial_stretch", "saddle_bend"), last
    assert not recording.exists() and not output.exists()

    out = subprocess.run([str(Path(sys.executable).parent / "yarnfit"), "fit", "cotton-jersey",
                          "--frictionless", "--yarn-model", "solid", "--figures", str(tmp_path / "figures"),
                          "--samples", SMALLEST_DESIGN, "--rerun", str(recording), "-o", str(output)],
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    # The default run ends on the bound of the block the strict run found indefinite, and says so.
    assert re.search(rf"note +(linear model: |symmetric bending: )?[sb]01 at the positive-definite bound .* {named.group(1)}", out.stdout), \
        out.stdout
    data = json.loads(output.read_text())
    coupling = {"biaxial_stretch": "s01", "saddle_bend": "b01"}[named.group(1)]
    assert coupling in data["fit"]["active_bounds"] and any(named.group(1) in n for n in data["fit"]["notes"])


# -- early errors, first run ----------------------------------------------------------------------

# An output checked before any computation fails in well under this (a fit's relaxation alone
# takes 10 s and more): the check ran first.
EARLY_ERROR_SECONDS = 5.0


def run_here(*args: str, cwd=None) -> subprocess.CompletedProcess:
    """``python -m yarnfit.cli`` with this checkout's yarnfit first on the path."""
    from test_tasks import checkout_env

    return subprocess.run([sys.executable, "-m", "yarnfit.cli", *args], capture_output=True, text=True, timeout=120,
                          cwd=cwd, env=checkout_env())


@pytest.mark.parametrize("command, option, what", [
    (("fit", "cotton-jersey"), ("-o", "{bad}/jersey.json"), "material file"),
    (("fit", "cotton-jersey"), ("--rerun", "{bad}/jersey.rrd"), "--rerun recording"),
    (("relax", "cotton-jersey"), ("--rerun", "{bad}/jersey.rrd"), "--rerun recording"),
    (("relax", "cotton-jersey"), ("-o", "{bad}/jersey.pyp"), "relaxed pattern"),
    (("validate", "{material}"), ("--logs", "{bad}/logs"), "--logs directory"),
])
def test_an_output_that_cannot_be_written_fails_first(command, option, what, tmp_path):
    """Every output path is checked writable before any computation: one line, exit 2."""
    blocker = tmp_path / "blocker"
    blocker.write_text("a file where a directory is needed")
    material = tmp_path / "m.json"
    material.write_text("{}")
    fill = {"bad": str(blocker), "material": str(material)}
    start = time.perf_counter()
    out = run_here(*[a.format(**fill) for a in command], option[0], option[1].format(**fill), cwd=tmp_path)
    assert time.perf_counter() - start < EARLY_ERROR_SECONDS
    assert out.returncode == 2, out.stderr
    assert len(out.stderr.strip().splitlines()) == 1 and what in out.stderr and "Traceback" not in out.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["blocker", "m.json"]


def test_first_compilation_is_announced():
    """Numba's compilations (not its cache loads) inside the block say so, once."""
    from numba import njit

    from yarnfit.cli import announce_compilation

    class Line:
        said = []

        def message(self, text, force=False):
            self.said.append(text)

    line = Line()

    @njit  # a new function, never cached: compiling it is a first run
    def twice(x):
        return 2 * x

    with announce_compilation(line):
        assert twice(2) == 4
        assert twice(2.5) == 5.0  # a second compilation says nothing more
    assert line.said == ["compiling kernels (first run only)"]
    with announce_compilation(line):
        twice(3)  # compiled already
    assert len(line.said) == 1


# -- show -----------------------------------------------------------------------------------------


def test_show_opens_each_kind_of_file_with_its_viewer(tmp_path, monkeypatch):
    """A material file's figures (drawn, then opened), a scene in MuJoCo's viewer, a recording in
    Rerun; anything else is a one-line error. The viewers themselves need a display: replaced."""
    from yarnfit import cli
    from test_plots import material_file  # a small fitted material written without a yarn-level fit

    opened = []
    monkeypatch.setattr(cli, "_open_figures", lambda paths: opened.append(("figures", paths)) or 0)
    monkeypatch.setattr(cli, "_view_scene", lambda path: opened.append(("scene", path)) or 0)
    monkeypatch.setattr(cli, "_view_recording", lambda path: opened.append(("recording", path)) or 0)
    material = material_file(tmp_path)
    assert cli.main(["show", str(material), "--figures", str(tmp_path / "figs")]) == 0
    kind, paths = opened[-1]
    assert kind == "figures" and paths and all(p.suffix == ".png" and p.parent == tmp_path / "figs" for p in paths)
    for suffix, kind in ((".xml", "scene"), (".rrd", "recording")):
        path = tmp_path / f"x{suffix}"
        path.write_text("")
        assert cli.main(["show", str(path)]) == 0 and opened[-1] == (kind, path)
    (tmp_path / "notes.txt").write_text("")
    assert cli.main(["show", str(tmp_path / "notes.txt")]) == 2
    (tmp_path / "other.json").write_text("{}")
    assert cli.main(["show", str(tmp_path / "other.json")]) == 2


def test_the_export_writes_the_splits_validate_runs():
    """yarnfit.mujoco's DRAPES_SPLIT and STRIPS_SPLIT (import-free, so the parser is built without
    MuJoCo) are the splits the drapes and the strips run (validate.drape and validate.stretch take
    their constants from them), each scene is exported with its kind's, and the export's help
    names them."""
    from yarnfit import cli
    from yarnfit.mujoco import DRAPES_SPLIT, EXPORT_SPLIT, STRIPS_SPLIT
    from yarnfit.validate import drape, stretch

    assert DRAPES_SPLIT == {"mesh": "crisscross", "membrane": "triangle", "implicit_share": "anisotropic",
                            "implicit_drag": "critical"}
    assert STRIPS_SPLIT == {"mesh": "crisscross", "membrane": "triangle", "implicit_share": "isotropic",
                            "implicit_drag": "critical"}
    assert (drape.MESH, drape.MEMBRANE, drape.IMPLICIT_SHARE, drape.IMPLICIT_DRAG) == tuple(DRAPES_SPLIT.values())
    assert (stretch.MESH, stretch.MEMBRANE, stretch.IMPLICIT_SHARE, stretch.IMPLICIT_DRAG) == tuple(STRIPS_SPLIT.values())
    assert EXPORT_SPLIT == {"cloth": DRAPES_SPLIT, "stretch": STRIPS_SPLIT, "sphere": DRAPES_SPLIT,
                            "wall": DRAPES_SPLIT}
    text = " ".join(cli.build_parser()._subparsers._group_actions[0].choices["export"].description.split())
    assert cli.split_options(DRAPES_SPLIT) in text and cli.split_options(STRIPS_SPLIT) in text
    assert (drape.SIZE, drape.RESOLUTION[False]) == (0.3, 25)  # "--size 0.3 --resolution 25" in the help
