"""Export of a fitted material to MuJoCo (yarnfit.mujoco): the split between MuJoCo's built-in
isotropic elasticity and the plugin, the isotropic fallback, the four scenes (built with MjSpec,
written as MJCF, reloaded with plain mujoco.MjModel.from_xml_path and stepped), and `yarnfit
export`."""

import dataclasses
import json
import math
import subprocess
import sys
import xml.etree.ElementTree as ElementTree
from pathlib import Path

import mujoco
import numpy as np
import pytest

from fabric_shell import FABRIC
from yarnfit.mujoco import DEFAULT_SIZE, SCENES
from yarnfit.mujoco.plugin import LIBRARY, PLUGIN_NAME
from yarnfit.mujoco.run import run_scene
from yarnfit.mujoco.scenes import (DEFAULT_STRIP_WIDTH, FLEX_RADIUS, VERTEX_CLASS, ClothMaterial, build_scene,
                                   compile_quietly, export_options, export_scene, strip_columns)
from yarnfit.mujoco.split import (MJCF_DIGITS, POISSON_LIMIT, builtin_elasticity, builtin_isotropic,
                                  isotropic_fallback, isotropic_stiffness)
from yarnfit.shell import RidgeMembrane, ShellMaterial

# The split's minimisation stops within 1e-10 in ν (POISSON_XATOL) at a kink of the objective; E
# and ν then agree with the closed form to ~1e-9. 1e-7 leaves room without hiding a wrong answer
# (a wrong branch is off by percents).
SPLIT_RTOL = 1e-7
# S_iso − S/2 is PSD up to the round-off of a 3×3 generalized eigenproblem: a few ε of ‖S‖.
PSD_ATOL = 1e-12
# The fallback is closed-form arithmetic (square roots, products): a few ulps.
ROUND_OFF_RTOL = 1e-12
# Fine grid for the independent check that no ν gives a smaller trace than the split's: the
# objective changes by ~|d tr/dν| × step²-ish near its minimum and by at most ~1e-3 relative per
# 1e-4 step elsewhere, so the split must not be beaten by more than that.
TRACE_GRID_STEP = 1e-4
TRACE_GRID_RTOL = 1e-3
# Stepping each exported scene: small grids, enough simulated time for the drops to hit their
# obstacle (0.02 m gap: 64 ms) and the stretch strip to be pulled.
RESOLUTION = 8
SECONDS = 0.2
AREAL_DENSITY = 0.2  # kg/m²
# A cloth resting on its obstacle: the top vertex sits a collision radius above it, give or take
# the contact's soft penetration (~1 mm at MuJoCo's default solref) and the grid's sag.
LANDING_ATOL = 3e-3
# An exported file against the scene built in memory: the file holds every number exactly and the
# same bodies, joints and triangles in the same order, so both compile to equal arrays and step
# alike to the last bit (measured). Round-off is the most a tolerance should forgive: the old 6-digit
# export put vertices 5e-7 m off, and flexcomp's even masses move a drape's by centimetres in 1 s.
EXPORT_STEPS = 300
TRAJECTORY_ATOL = 1e-12  # m


def isotropic(young, poisson, thickness) -> ShellMaterial:
    """S = E C(ν) and Kirchhoff's plate bending: (h³/2) κᵀ B κ = (D/2) (κ11² + κ22² + 2ν κ11 κ22
    + 2(1 − ν) κ12²) with D = E h³/(12 (1 − ν²)), i.e. b00 = b11 = D/h³, b01 = ν b00,
    b22 = (1 − ν) b00 / 2."""
    s00 = young / (1 - poisson**2)
    b00 = s00 / 12
    return ShellMaterial(thickness=thickness, s00=s00, s01=poisson * s00, s11=s00, s22=young / (2 * (1 + poisson)),
                         b00=b00, b01=poisson * b00, b11=b00, b22=(1 - poisson) * b00 / 2)


def random_materials(count, seed=11):
    """Orthotropic materials with anisotropy up to 1e3 between weft, warp and shear."""
    rng = np.random.default_rng(seed)
    for _ in range(count):
        s00, s11, s22 = 10.0 ** rng.uniform(5, 8, 3)
        rho = rng.uniform(-0.95, 0.95)
        yield ShellMaterial(thickness=10 ** rng.uniform(-4, -3), s00=s00, s01=rho * math.sqrt(s00 * s11), s11=s11,
                            s22=s22, b00=1e6, b01=0.0, b11=2e6, b22=5e5)


def least_young_closed_form(material, poisson):
    """Least E with E C(ν) ⪰ S/2, by the eigenvectors of C(ν) (not the generalized eigensolver):
    in the basis (1, 1)/√2, (1, −1)/√2 the membrane block of C(ν) is diag(1/(1 − ν), 1/(1 + ν))."""
    Q = np.array([[1.0, 1.0], [1.0, -1.0]]) / math.sqrt(2)
    root = np.diag([math.sqrt(1 - poisson), math.sqrt(1 + poisson)])  # C^(-1/2) in that basis
    half = 0.5 * material.S[:2, :2]
    membrane = np.linalg.eigvalsh(root @ Q.T @ half @ Q @ root)[-1]
    return max(membrane, material.s22 * (1 + poisson))  # shear: E/(2(1 + ν)) ≥ s22/2


def trace_per_young(poisson):
    return 2 / (1 - poisson**2) + 1 / (2 * (1 + poisson))


# -- the split ---------------------------------------------------------------------------------


@pytest.mark.parametrize("poisson", [0.0, 0.2, 0.45])
def test_split_of_an_isotropic_material_is_half_of_it(poisson):
    # S = E0 C(ν0): S_iso ⪰ S/2 has tr S_iso ≥ tr S/2, with equality only at S_iso = S/2, so
    # (E, ν) = (E0/2, ν0).
    young = 3.0e6
    part = builtin_isotropic(isotropic(young, poisson, 3e-4))
    assert part.young_pa == pytest.approx(young / 2, rel=SPLIT_RTOL)
    assert part.poisson == pytest.approx(poisson, rel=SPLIT_RTOL, abs=SPLIT_RTOL)


def test_split_of_a_too_incompressible_isotropic_material_stops_at_the_poisson_limit():
    # ν0 = 0.6 > POISSON_LIMIT: the least E at the bound is still ⪰ S/2.
    material = isotropic(3.0e6, 0.6, 3e-4)
    part = builtin_isotropic(material)
    assert part.poisson == pytest.approx(POISSON_LIMIT, abs=SPLIT_RTOL)
    assert part.young_pa == pytest.approx(least_young_closed_form(material, POISSON_LIMIT), rel=SPLIT_RTOL)


@pytest.mark.parametrize("material", [FABRIC, *random_materials(6)], ids=lambda m: f"s00={m.s00:.3g}")
def test_split_covers_half_the_material_with_least_trace(material):
    part = builtin_isotropic(material)
    assert 0.0 <= part.poisson <= POISSON_LIMIT
    S = material.S
    # The explicit remainder S − S_iso lies between −S_iso and S_iso.
    assert np.linalg.eigvalsh(isotropic_stiffness(*part) - S / 2).min() >= -PSD_ATOL * np.abs(S).max()
    assert np.linalg.eigvalsh(isotropic_stiffness(*part) - (S - isotropic_stiffness(*part))).min() >= \
        -PSD_ATOL * np.abs(S).max()
    # Least trace, against a brute-force scan of the closed form.
    grid = np.arange(0.0, POISSON_LIMIT + TRACE_GRID_STEP / 2, TRACE_GRID_STEP)
    best = min(least_young_closed_form(material, nu) * trace_per_young(nu) for nu in grid)
    ours = part.young_pa * trace_per_young(part.poisson)
    assert ours <= best * (1 + SPLIT_RTOL)
    assert ours >= best * (1 - TRACE_GRID_RTOL)


@pytest.mark.parametrize("material", [FABRIC, *random_materials(3, seed=5)], ids=lambda m: f"s00={m.s00:.3g}")
def test_split_written_to_mjcf_is_representable_and_still_covers_half(material):
    split = builtin_elasticity(material)
    for value in (split.young_pa, split.poisson, split.thickness_m):
        assert float(f"{value:.{MJCF_DIGITS}g}") == value  # what spec.to_xml() writes, read back
    # h_b E_b C(ν_b) ⪰ h S/2 (per area: the thicknesses differ by the rounding).
    builtin = split.thickness_m * isotropic_stiffness(split.young_pa, split.poisson)
    half = material.thickness * material.S / 2
    assert np.linalg.eigvalsh(builtin - half).min() >= -PSD_ATOL * np.abs(half).max()
    # Its hinge bending ½ D (κ00² + κ11² + 2 κ01²) at least the material's ½ h³ κᵀ B κ in every mode.
    assert split.bending and split.elastic2d == "both"
    hinge = split.bending_rigidity_nm * np.diag([1.0, 1.0, 0.5])
    full = material.thickness**3 * material.B
    assert np.linalg.eigvalsh(hinge - full).min() >= -PSD_ATOL * np.abs(full).max()
    # Without the bending share the built-in part is the material's thickness and stretches only.
    stretch_only = builtin_elasticity(material, bending=False)
    assert not stretch_only.bending and stretch_only.elastic2d == "stretch"
    assert stretch_only.bending_rigidity_nm == 0.0
    assert stretch_only.thickness_m == float(f"{material.thickness:.{MJCF_DIGITS}g}")


def test_split_with_a_stiffening_bound_covers_half_the_largest_tangent():
    """With ``stiffening_bound`` the built-in membrane covers half the ridge membrane's largest
    tangent up to that strain, more than without it, and exactly the linear split for a material
    without a ridge membrane."""
    s = FABRIC
    stiff = dataclasses.replace(s, nonlinear=RidgeMembrane((s.s00, s.s01, s.s11, s.s22), (
        (1.0, 0.0, 0.0, 0.02, 20.0 * s.s00), (0.0, 1.0, 0.0, 0.03, 20.0 * s.s11))))
    bound = 0.05
    split = builtin_elasticity(stiff, stiffening_bound=bound)
    builtin = split.thickness_m * isotropic_stiffness(split.young_pa, split.poisson)
    half = stiff.thickness * stiff.nonlinear.largest_tangent(bound) / 2
    assert np.linalg.eigvalsh(builtin - half).min() >= -PSD_ATOL * np.abs(half).max()
    plain = builtin_elasticity(stiff, stiffening_bound=0.0)
    assert split.young_pa * split.thickness_m > 1.5 * plain.young_pa * plain.thickness_m
    assert builtin_elasticity(s, stiffening_bound=bound) == builtin_elasticity(s)


# -- the fallback ------------------------------------------------------------------------------


@pytest.mark.parametrize("poisson", [0.0, 0.3, 0.45])
def test_fallback_of_an_isotropic_material_is_itself(poisson):
    young, thickness = 2.0e6, 3.0e-4
    fallback = isotropic_fallback(isotropic(young, poisson, thickness))
    assert fallback.young_pa == pytest.approx(young, rel=ROUND_OFF_RTOL)
    assert fallback.poisson == pytest.approx(poisson, rel=ROUND_OFF_RTOL, abs=ROUND_OFF_RTOL)
    assert fallback.thickness_m == pytest.approx(thickness, rel=ROUND_OFF_RTOL)
    assert fallback.notes == ()


def test_fallback_matches_the_geometric_means_of_stretch_and_bending():
    eng = FABRIC.engineering()
    young, poisson, thickness, notes = isotropic_fallback(FABRIC)
    # E h = √(weft · warp) (N/m); E h³/(12 (1 − ν²)) = √(bending weft · bending warp) (N·m).
    assert young * thickness == pytest.approx(math.sqrt(eng["weft_stretch_n_per_m"] * eng["warp_stretch_n_per_m"]),
                                              rel=ROUND_OFF_RTOL)
    assert young * thickness**3 / (12 * (1 - poisson**2)) == pytest.approx(
        math.sqrt(eng["bending_weft_nm"] * eng["bending_warp_nm"]), rel=ROUND_OFF_RTOL)
    assert poisson == pytest.approx(math.sqrt(eng["poisson_weft"] * eng["poisson_warp"]), rel=ROUND_OFF_RTOL)
    assert any("anisotropy lost" in note for note in notes)


@pytest.mark.parametrize("s01, expected", [(0.99, POISSON_LIMIT), (-0.2, 0.0)])
def test_fallback_says_when_it_limits_the_poisson_ratio(s01, expected):
    # A knit-like coupling (geometric mean ν near 1) and a negative one: neither is in MuJoCo's [0, 0.5).
    material = ShellMaterial(thickness=3e-4, s00=1e6, s01=s01 * math.sqrt(2) * 1e6, s11=2e6, s22=1e5,
                             b00=1e6, b01=0.0, b11=1e6, b22=3e5)
    fallback = isotropic_fallback(material)
    assert fallback.poisson == expected
    assert any("Poisson ratio limited" in note for note in fallback.notes)


def test_fallback_of_ratios_of_opposite_signs_is_zero_and_says_so():
    # A ridge membrane whose weft pull widens it and whose warp pull narrows it (a knit's courses
    # and wales can): ridge A along (1, -1)/√2 couples negatively once the weft leads, ridge B along
    # (1, 1)/√2 positively in both pulls, A the stiffer.
    diagonal = 1.0 / math.sqrt(2.0)
    ridges = ((diagonal, -diagonal, 0.0, 0.0, 0.6 * FABRIC.s00), (diagonal, diagonal, 0.0, 0.0, 0.2 * FABRIC.s00))
    material = dataclasses.replace(FABRIC, nonlinear=RidgeMembrane((FABRIC.s00, 0.0, FABRIC.s11, FABRIC.s22), ridges))
    eng = material.engineering()
    assert eng["poisson_weft"] < 0.0 < eng["poisson_warp"]
    fallback = isotropic_fallback(material)
    assert fallback.poisson == 0.0
    assert any("opposite signs" in note for note in fallback.notes)


# -- scenes ------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def material_file(tmp_path_factory):
    """A minimal material file: the shell and the label's areal density."""
    path = tmp_path_factory.mktemp("material") / "woven.json"
    path.write_text(json.dumps({"inputs": {"fabric": "woven", "areal_density_kg_m2": AREAL_DENSITY},
                                "shell": FABRIC.to_dict()}))
    return path


def plugin_config(path) -> dict:
    return mujoco.MjSpec.from_file(str(path)).plugins[0].config


@pytest.mark.parametrize("scene", SCENES)
def test_scene_exports_reloads_and_runs_stably(scene, material_file, tmp_path):
    path = tmp_path / f"{scene}.xml"
    built = export_scene(material_file, scene, path, resolution=RESOLUTION)
    model = mujoco.MjModel.from_xml_path(str(path))  # plain MuJoCo: the plugin comes from the entry point
    assert model.nplugin == 1 and model.nflex == 1
    config = plugin_config(path)
    # The full material, exactly, with node-smoothed strains: the plugin removes the flex's
    # <elasticity> exactly (it stays in MuJoCo's implicit matrix) and needs no builtin_* keys.
    for name, value in FABRIC.parameters.items():
        assert float(config[name]) == value
    assert float(config["thickness"]) == FABRIC.thickness
    assert config["membrane"] == "node"
    assert "implicit_drag" not in config  # the full drag, the plugin's default (plugins/README.md)
    assert not any(key.startswith("builtin_") for key in config)
    flex = mujoco.MjSpec.from_file(str(path)).flexes[0]
    assert (flex.young, flex.poisson, flex.thickness, flex.elastic2d) == \
        (built.young_pa, built.poisson, built.thickness_m, 3)  # both: the built-in part bends too
    # The cloth's mass is its area times the areal density (pinned vertices' share aside).
    report = run_scene(path, SECONDS)
    assert report.stable, report
    assert report.steps == round(SECONDS / model.opt.timestep)


@pytest.mark.parametrize("scene", ["cloth", "sphere"])
def test_fallback_scene_has_no_plugin_and_runs_stably(scene, material_file, tmp_path):
    path = tmp_path / f"{scene}-fallback.xml"
    built = export_scene(material_file, scene, path, resolution=RESOLUTION, fallback=True)
    model = mujoco.MjModel.from_xml_path(str(path))
    assert model.nplugin == 0
    root = ElementTree.parse(path).getroot()
    assert root.find("extension") is None and root.find(".//plugin") is None
    fallback = isotropic_fallback(FABRIC)
    assert (built.young_pa, built.poisson, built.thickness_m) == fallback[:3]
    assert mujoco.MjSpec.from_file(str(path)).flexes[0].elastic2d == 3  # both: stretch and bending
    assert run_scene(path, SECONDS).stable


@pytest.mark.parametrize("scene", ["sphere", "wall"])
def test_dropped_cloth_lands_on_its_obstacle(scene, material_file):
    # Both obstacles are 0.6 size = 0.3 m tall; the cloth starts DROP_GAP above and must rest on top
    # (its highest vertex one collision radius above it), not fall past: MuJoCo collides vertices,
    # and this coarse grid's columns straddle a 2 cm wall unless the scene thickens it.
    built = build_scene(ClothMaterial.from_file(material_file), scene, resolution=RESOLUTION)
    model = built.spec.compile()
    data = mujoco.MjData(model)
    while data.time < 1.5 * SECONDS:
        mujoco.mj_step(model, data)
    mujoco.mj_forward(model, data)
    assert data.flexvert_xpos[:, 2].max() == pytest.approx(0.3 + FLEX_RADIUS, abs=LANDING_ATOL)


def test_vertex_masses_carry_the_areal_density(material_file):
    built = build_scene(ClothMaterial.from_file(material_file), "sphere", resolution=RESOLUTION, size=0.4)
    model = built.spec.compile()
    bodies = np.unique(model.flex_vertbodyid)
    assert model.body_mass[bodies].sum() == pytest.approx(AREAL_DENSITY * 0.4**2, rel=ROUND_OFF_RTOL)


def test_stretch_clamp_pulls_and_reads_a_tension(material_file):
    # Ramped to 10 % strain over the run: the servo force is the strip's tension, between the
    # free-width uniaxial stiffness and the width-held (s00 h) one times the extension.
    built = build_scene(ClothMaterial.from_file(material_file), "stretch", resolution=9)
    model = built.spec.compile()
    data = mujoco.MjData(model)
    pull = model.actuator("pull").id
    target = model.actuator_ctrlrange[pull, 1]
    steps = round(SECONDS / model.opt.timestep)
    for step in range(steps):
        data.ctrl[pull] = target * min(1.0, 2 * (step + 1) / steps)  # ramp, then hold
        mujoco.mj_step(model, data)
    force, extension = data.sensor("pull_force").data[0], data.sensor("pull_extension").data[0]
    length, width = 0.08, 0.05
    strain = extension / length
    eng = FABRIC.engineering()
    assert extension == pytest.approx(target, rel=0.05)  # the servo is 100× stiffer than the strip
    # Held width at 10 %: h s00 times the Green strain 0.105 and the stretch 1.1 (PK1 = λ S E) is
    # 1.155 h s00 × strain; free width is the lower bound.
    assert eng["weft_stretch_n_per_m"] * width * strain < force < 1.2 * FABRIC.thickness * FABRIC.s00 * width * strain


def test_run_scene_reports_an_unstable_scene(material_file):
    # Explicit Euler at 1 ms is above this coarse grid's explicit limit (measured: stable from 0.25 ms
    # down with the default damping, which Euler also integrates explicitly).
    built = build_scene(ClothMaterial.from_file(material_file), "cloth", resolution=RESOLUTION,
                        integrator="euler", timestep=1e-3)
    report = run_scene(built.spec, SECONDS)
    assert not report.stable and report.bad_qacc >= 1
    assert report.steps < round(SECONDS / 1e-3)


def test_bad_scene_options_fail_clearly(material_file):
    material = ClothMaterial.from_file(material_file)
    with pytest.raises(ValueError, match="unknown scene 'drape'"):
        build_scene(material, "drape")
    with pytest.raises(ValueError, match="resolution must be an integer of at least 2"):
        build_scene(material, "cloth", resolution=0)
    with pytest.raises(ValueError, match="unknown integrator 'implicitfast'"):
        build_scene(material, "cloth", integrator="implicitfast")
    with pytest.raises(ValueError, match="unknown implicit_drag 'half'"):
        build_scene(material, "cloth", implicit_drag="half")
    with pytest.raises(ValueError, match="unknown solver 'pgs'; solvers: newton, cg"):
        build_scene(material, "sphere", solver="pgs")
    # The soft modes' drag given back when asked (written; "full", the plugin's default, is left out).
    config = build_scene(material, "cloth", implicit_drag="critical").spec.plugins[0].config
    assert config["implicit_drag"] == "critical"


def test_material_file_errors_name_the_problem(tmp_path):
    with pytest.raises(ValueError, match="no such material file"):
        ClothMaterial.from_file(tmp_path / "missing.json")
    bad = tmp_path / "bad.json"
    bad.write_text("{ not json")
    with pytest.raises(ValueError, match="invalid JSON"):
        ClothMaterial.from_file(bad)
    no_density = tmp_path / "no-density.json"
    no_density.write_text(json.dumps({"shell": FABRIC.to_dict()}))
    with pytest.raises(ValueError, match="no areal density"):
        ClothMaterial.from_file(no_density)
    assert ClothMaterial.from_file(no_density, 0.15).areal_density_kg_m2 == 0.15


# -- command line ------------------------------------------------------------------------------


def yarnfit(*args: str) -> subprocess.CompletedProcess:
    script = Path(sys.executable).parent / "yarnfit"
    return subprocess.run([str(script), *args], capture_output=True, text=True, timeout=120)


def test_cli_export_writes_a_scene_that_loads(material_file, tmp_path):
    path = tmp_path / "wall.xml"
    out = yarnfit("export", str(material_file), "--scene", "wall", "--resolution", "6", "-o", str(path),
                  "--check", "0.05")
    assert out.returncode == 0, out.stderr
    # The wall is exported with the drapes' split unless told (yarnfit.mujoco.EXPORT_SPLIT).
    assert "built-in" in out.stdout and "stable" in out.stdout and "implicit_drag critical" in out.stdout
    assert "implicit_share anisotropic" in out.stdout and "triangle membrane strains on crisscross cells" in out.stdout
    # A fresh interpreter with nothing but `import mujoco`: our entry point registers the plugin.
    plain = subprocess.run([sys.executable, "-c", "import sys, mujoco; "
                            "print(mujoco.MjModel.from_xml_path(sys.argv[1]).nplugin)", str(path)],
                           capture_output=True, text=True, timeout=60)
    assert plain.returncode == 0 and plain.stdout.strip() == "1", plain.stderr


@pytest.mark.parametrize("options", [(), ("--mesh", "crisscross", "--membrane", "triangle", "--implicit-share",
                                           "anisotropic", "--implicit-drag", "critical")])
def test_cli_export_writes_the_validated_drapes_split(material_file, tmp_path, options):
    """The split `yarnfit validate` drapes with (yarnfit.mujoco.DRAPES_SPLIT) is the sphere's by
    default, and as options: criss-cross cells, triangle strains, the anisotropic share and the
    critical drag reach the file, and the scene is the drapes' own to the vertex."""
    from yarnfit.validate import drape

    path = tmp_path / "sphere.xml"
    out = yarnfit("export", str(material_file), "--scene", "sphere", "--resolution", "6", "-o", str(path), *options)
    assert out.returncode == 0, out.stderr
    assert "triangle membrane strains" in out.stdout and "CG solver" in out.stdout
    config = mujoco.MjSpec.from_file(str(path)).plugins[0].config
    # Triangle strains are the plugin's own default: the key is written only for node strains.
    assert "membrane" not in config and config["implicit_drag"] == "critical" and "implicit_share" in config
    exported = mujoco.MjModel.from_xml_path(str(path))
    assert exported.nflexvert == 6 * 6 + 5 * 5
    material = ClothMaterial.from_file(material_file)
    validated = compile_quietly(drape._square_spec(material, "sphere", 6))
    np.testing.assert_array_equal(exported.flex_elem, validated.flex_elem)
    assert exported.opt.solver == validated.opt.solver


@pytest.mark.parametrize("args, message", [
    (["missing.json", "--scene", "cloth"], "no such material file"),
    (["{material}", "--scene", "drape"], "invalid choice: 'drape'"),
    (["{material}", "--scene", "cloth", "--resolution", "0"], "--resolution must be at least 2"),
    (["{bad}", "--scene", "cloth"], "invalid JSON"),
])
def test_cli_export_bad_input_is_one_line_and_status_2(args, message, material_file, tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text("[1, 2")
    args = [a.format(material=material_file, bad=bad) for a in args]
    out = yarnfit("export", *args, "-o", str(tmp_path / "x.xml"))
    assert out.returncode == 2
    assert message in out.stderr and len(out.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "x.xml").exists()


# -- the exported file ------------------------------------------------------------------------


def differing_arrays(a: mujoco.MjModel, b: mujoco.MjModel) -> list[str]:
    """The names of the mjModel arrays (and mjOption fields) in which ``a`` and ``b`` differ."""
    names = [name for name in dir(a) if not name.startswith("_") and isinstance(getattr(a, name), np.ndarray)]
    differ = [name for name in names if not np.array_equal(getattr(a, name), getattr(b, name), equal_nan=True)]
    return differ + [f"opt.{name}" for name in dir(a.opt) if not name.startswith("_")
                     and not np.array_equal(getattr(a.opt, name), getattr(b.opt, name))]


def stepped_qpos(model: mujoco.MjModel, steps: int) -> np.ndarray:
    """``qpos`` after each of ``steps`` steps ``(steps, nq)``; the stretch clamp ramps to its largest
    control over the run."""
    data = mujoco.MjData(model)
    qpos = np.empty((steps, model.nq))
    for step in range(steps):
        if model.nu:
            data.ctrl[:] = model.actuator_ctrlrange[:, 1] * (step + 1) / steps
        mujoco.mj_step(model, data)
        qpos[step] = data.qpos
    return qpos


@pytest.mark.parametrize("fallback", [False, True], ids=["plugin", "fallback"])
@pytest.mark.parametrize("scene", SCENES)
def test_exported_scene_compiles_to_the_built_model(scene, fallback, material_file, tmp_path):
    """The exported file is the scene build_scene builds: the same dofs and what they move, vertex
    positions and lumped masses, pins, plugin and its config, <elasticity>, contacts, options,
    actuators and sensors; every mjModel array equal, and the same motion."""
    material = ClothMaterial.from_file(material_file)
    built = build_scene(material, scene, resolution=RESOLUTION, fallback=fallback)
    path = tmp_path / f"{scene}.xml"
    export_scene(material, scene, path, resolution=RESOLUTION, fallback=fallback)
    memory, file = compile_quietly(built.spec), mujoco.MjModel.from_xml_path(str(path))

    assert (file.nq, file.nv, file.nbody, file.nflexvert) == (memory.nq, memory.nv, memory.nbody, memory.nflexvert)
    np.testing.assert_array_equal(file.jnt_type, memory.jnt_type)
    np.testing.assert_array_equal(file.jnt_axis, memory.jnt_axis)
    np.testing.assert_array_equal(file.jnt_bodyid, memory.jnt_bodyid)
    np.testing.assert_array_equal(file.flex_vertbodyid, memory.flex_vertbodyid)  # the pins
    np.testing.assert_array_equal(file.flex_elem, memory.flex_elem)
    vertex_bodies = np.unique(memory.flex_vertbodyid[memory.body_dofnum[memory.flex_vertbodyid] == 3])
    np.testing.assert_array_equal(file.body_mass[vertex_bodies], memory.body_mass[vertex_bodies])
    for name in ("flex_stiffness", "flex_bending", "flex_damping", "flex_radius", "flex_friction", "flex_contype",
                 "flex_conaffinity", "flex_selfcollide"):
        np.testing.assert_array_equal(getattr(file, name), getattr(memory, name), err_msg=name)
    spec = mujoco.MjSpec.from_file(str(path))
    assert (spec.flexes[0].young, spec.flexes[0].poisson, spec.flexes[0].thickness, spec.flexes[0].elastic2d) == \
        (built.young_pa, built.poisson, built.thickness_m, 3)
    assert file.nplugin == memory.nplugin == (0 if fallback else 1)
    if not fallback:
        assert spec.plugins[0].config == built.spec.plugins[0].config
        assert spec.plugins[0].config["membrane"] == "node"
    assert (file.opt.timestep, file.opt.integrator, file.opt.solver) == \
        (memory.opt.timestep, memory.opt.integrator, memory.opt.solver)
    np.testing.assert_array_equal(file.opt.gravity, memory.opt.gravity)
    for name in ("actuator_gainprm", "actuator_biasprm", "actuator_ctrlrange", "sensor_type", "sensor_objid"):
        np.testing.assert_array_equal(getattr(file, name), getattr(memory, name), err_msg=name)
    assert differing_arrays(file, memory) == []

    at_rest = []
    for model in (memory, file):
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        at_rest.append(data.flexvert_xpos.copy())
    np.testing.assert_array_equal(at_rest[1], at_rest[0])
    np.testing.assert_allclose(stepped_qpos(file, EXPORT_STEPS), stepped_qpos(memory, EXPORT_STEPS),
                               rtol=0, atol=TRAJECTORY_ATOL)


@pytest.mark.parametrize("scene", SCENES)
def test_the_cloth_flex_is_named_cloth(scene, material_file, tmp_path):
    """Every scene's flex is found by the name ``cloth``, in memory and in the exported file, and the
    body holding its vertex v is ``cloth_<v>`` (flexcomp's names), or the world or the clamp for a
    pinned vertex."""
    material = ClothMaterial.from_file(material_file)
    path = tmp_path / f"{scene}.xml"
    export_scene(material, scene, path, resolution=RESOLUTION)
    across = strip_columns(RESOLUTION, DEFAULT_SIZE["stretch"], DEFAULT_STRIP_WIDTH)  # stretch: vertex ix across + iy
    holder = {"cloth": {0: "world", RESOLUTION - 1: "world"}, "sphere": {}, "wall": {},
              "stretch": {v: "world" if v < across else "clamp" for v in range(RESOLUTION * across)
                          if v // across in (0, RESOLUTION - 1)}}[scene]
    for model in (compile_quietly(build_scene(material, scene, resolution=RESOLUTION).spec),
                  mujoco.MjModel.from_xml_path(str(path))):
        flex = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_FLEX, "cloth")
        assert flex >= 0
        start = model.flex_vertadr[flex]
        for v in range(model.flex_vertnum[flex]):
            body = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, model.flex_vertbodyid[start + v])
            assert body == holder.get(v, f"cloth_{v}")


@pytest.mark.parametrize("fallback", [False, True], ids=["plugin", "fallback"])
@pytest.mark.parametrize("scene", ["cloth", "stretch"])
def test_exported_file_says_what_it_needs(scene, fallback, material_file, tmp_path):
    """The file opens with a comment that names the plugin, what it carries and how to get it (pip,
    the entry point, mj_loadPluginLibrary on the library, the fallback option) and why the cloth is
    not a <flexcomp>; MuJoCo keeps that comment when it saves the model, and the file is well-formed
    XML (no ``--`` inside a comment)."""
    path = tmp_path / f"{scene}.xml"
    export_scene(material_file, scene, path, resolution=RESOLUTION, fallback=fallback)
    text = path.read_text()
    ElementTree.parse(path)  # raises on malformed XML
    comment = mujoco.MjSpec.from_file(str(path)).comment
    assert text.index(comment) < text.index("<option")  # first, before any element
    header = " ".join(comment.split())  # as a paragraph
    assert PLUGIN_NAME in header and "pip install yarnfit" in header
    if fallback:
        assert "no plugin" in header and "fallback option" in header
    else:
        for needed in ("mujoco.plugins", "mj_loadPluginLibrary", LIBRARY.name, "fallback option",
                       'membrane="node"', "not found"):
            assert needed in header, needed
    assert "Not a <flexcomp>" in header and "same mass" in header
    assert ("clamp" in header) == (scene == "stretch")  # flexcomp pins to one body only
    assert f'<frame childclass="{VERTEX_CLASS}">' in text
    assert comment in mujoco.MjSpec.from_file(str(path)).to_xml()


def test_cli_export_with_the_anisotropic_share(material_file, tmp_path):
    """`--implicit-share anisotropic` writes the plugin's implicit_share key; loaded in a fresh
    interpreter (`import mujoco` alone), the plugin rewrites MuJoCo's membrane metric from it, as
    build_scene's model has it."""
    path = tmp_path / "cloth.xml"
    out = yarnfit("export", str(material_file), "--scene", "cloth", "--resolution", "6", "-o", str(path),
                  "--implicit-share", "anisotropic", "--check", "0.05")
    assert out.returncode == 0, out.stderr
    assert "implicit_share anisotropic" in out.stdout and "stable" in out.stdout
    assert 'key="implicit_share"' in path.read_text()
    plain = subprocess.run([sys.executable, "-c", "import sys, mujoco, numpy; m = mujoco.MjModel.from_xml_path(sys.argv[1]); "
                            "mujoco.MjData(m); numpy.save(sys.argv[2], m.flex_stiffness)", str(path),
                            str(tmp_path / "metric.npy")], capture_output=True, text=True, timeout=60)
    assert plain.returncode == 0, plain.stderr
    built = build_scene(ClothMaterial.from_file(material_file), "cloth",
                        **export_options("cloth", resolution=6, implicit_share="anisotropic"))
    model = built.spec.compile()
    np.testing.assert_array_equal(np.load(tmp_path / "metric.npy"), model.flex_stiffness)


def test_export_options_fill_in_the_scenes_split_and_keep_what_is_given():
    """export_options: each scene's EXPORT_SPLIT and EXPORT_RESOLUTION where nothing (or None) is
    given, what is given kept; an unknown scene refused."""
    from yarnfit.mujoco import DRAPES_SPLIT, EXPORT_RESOLUTION, STRIPS_SPLIT

    assert export_options("sphere") == {"resolution": EXPORT_RESOLUTION["sphere"], **DRAPES_SPLIT}
    assert export_options("stretch", mesh=None) == {"resolution": EXPORT_RESOLUTION["stretch"], **STRIPS_SPLIT}
    given = export_options("cloth", resolution=12, mesh="grid", membrane="node", size=0.3)
    assert given == {**DRAPES_SPLIT, "resolution": 12, "mesh": "grid", "membrane": "node", "size": 0.3}
    with pytest.raises(ValueError, match="unknown scene 'bed'"):
        export_options("bed")


def test_each_scene_has_its_solver_and_the_file_keeps_it(material_file, tmp_path):
    """CG where the cloth touches something, Newton for the strip (yarnfit.mujoco.DEFAULT_SOLVER:
    CG twice as fast as Newton on the sphere, 3.2 times slower on the clamped strip); an explicit
    solver wins, in any case, and reaches the written file."""
    material = ClothMaterial.from_file(material_file)
    expected = {"cloth": mujoco.mjtSolver.mjSOL_CG, "sphere": mujoco.mjtSolver.mjSOL_CG,
                "wall": mujoco.mjtSolver.mjSOL_CG, "stretch": mujoco.mjtSolver.mjSOL_NEWTON}
    assert set(expected) == set(SCENES)
    for scene, solver in expected.items():
        assert build_scene(material, scene, resolution=RESOLUTION).spec.option.solver == solver, scene
    path = tmp_path / "sphere.xml"
    export_scene(material, "sphere", path, resolution=RESOLUTION, solver="Newton")
    assert mujoco.MjModel.from_xml_path(str(path)).opt.solver == mujoco.mjtSolver.mjSOL_NEWTON
