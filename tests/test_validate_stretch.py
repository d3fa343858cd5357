"""The suite's FAB-style stretch test in MuJoCo (yarnfit.validate.stretch) and measured reference
curves (yarnfit.validate.reference)."""

import math
import threading

import numpy as np
import pytest
import rerun as rr

from fabric_shell import FABRIC
from yarnfit.mujoco.scenes import ClothMaterial, grid_mesh
from yarnfit.shell import RidgeMembrane, ShellMaterial
from yarnfit.validate.shell_strip import shell_strip_limit
from yarnfit.validate.reference import read_reference
from yarnfit.validate import DIRECTIONS
from yarnfit.validate.stretch import StripResult, pull_strip, quasi_static_forces, run_stretch
from yarnfit.validate.verdicts import STRIPS_FOLLOW_SHELL_RTOL

# The bound for the scene against the shell law at small strain (the clamped law on the
# scene's mesh, with the strips' constant-strain triangles). Measured on the quick 9 × 6 strip at
# 0.2 % strain: within 1.6 % (the woven's bias), the presets within 1.1 % (validation of issue 6);
# with node-smoothed strains the six cases below came within +0.30 % to +0.47 %.
LAW_RTOL = 0.03
SERVO_LAG_RTOL = 0.04
# Areal density of the test materials (kg/m²).
DENSITY = 0.2

WOVEN = ClothMaterial("woven", FABRIC, DENSITY)
# Isotropic, Poisson 0: clamped ends hold nothing back, the strip is in uniaxial tension.
H = 3.0e-4
E = 1.0e3 / H
NO_POISSON = ClothMaterial("no-poisson", ShellMaterial(thickness=H, s00=E, s01=0.0, s11=E, s22=E / 2,
                                                        b00=1e-5 / H**3, b01=0.0, b11=1e-5 / H**3, b22=5e-6 / H**3),
                           DENSITY)


# A knit-like orthotropic material: Poisson ratios 0.7 and 1.0, soft in shear, so that clamped
# ends stiffen an 8 × 5 strip well beyond the uniaxial law (factor ~2.5).
KNIT = ClothMaterial("knit", ShellMaterial(thickness=H, s00=2.0e6, s01=2.5e6, s11=4.0e6, s22=0.5e6,
                                           b00=1e-5 / H**3, b01=0.0, b11=1e-5 / H**3, b22=5e-6 / H**3), DENSITY)


@pytest.mark.parametrize("material, direction", [(NO_POISSON, "weft"), (WOVEN, "weft"), (WOVEN, "warp"),
                                                 (WOVEN, "bias"), (KNIT, "weft"), (KNIT, "bias")])
def test_small_strain_force_follows_the_clamped_shell_law(material, direction):
    """The scene against an independent linear solve of the same clamped strip (the issue's 3 %)."""
    result = pull_strip(material, "8x5", direction, quick=True, max_strain=0.002)
    assert result.settled.all()
    assert result.force_per_width_n_per_m[0] / result.strain[0] == pytest.approx(result.clamped_law_n_per_m,
                                                                                  rel=LAW_RTOL)
    # Measured strain, not the servo's target. The servo is 100 times the strip's stiffer uniaxial
    # stiffness, so it lags ~1 %; clamped strips of strongly contracting materials are up to ~3
    # times stiffer than that (the knit's bias) and lag up to ~3 %.
    assert result.strain[0] == pytest.approx(0.002, rel=SERVO_LAG_RTOL)


# Discretisation error of the linear reference on the grids below against the closed forms; the
# long strip's end zones (a width long, where the clamps hold the contraction) add ~ν² W/L.
CLOSED_FORM_RTOL = 0.02


@pytest.mark.parametrize("smoothing", ["triangle", "node"])
@pytest.mark.parametrize("angle", [0.0, math.pi / 2, math.pi / 4, 0.3])
def test_clamped_strip_law_without_poisson_is_the_uniaxial_law(angle, smoothing):
    """Without Poisson coupling the clamped strip is in uniform uniaxial strain, which both
    constant-strain triangles and node-smoothed strains carry exactly, on any mesh."""
    from yarnfit.mujoco.scenes import panel_mesh
    from yarnfit.validate.stretch import clamped_strip_stiffness

    shell = NO_POISSON.shell
    if angle not in (0.0, math.pi / 2):
        # Rotated axes couple shear into the pull: only the isotropic no-Poisson law stays uniaxial.
        shell = ShellMaterial(thickness=H, s00=E, s01=0.0, s11=E, s22=E / 2, b00=1.0, b01=0.0, b11=1.0, b22=0.5)
    for points, triangles in (grid_mesh(9, 6, 0.08, 0.05),
                              panel_mesh(np.array([[-0.04, -0.025], [0.04, -0.025], [0.04, 0.025], [-0.04, 0.025]]),
                                         0.01)):
        assert clamped_strip_stiffness(shell, points, triangles, angle, smoothing) == pytest.approx(E * H, rel=1e-9)


def test_node_smoothed_strains_free_the_meshes_that_lock():
    """A woven cut on the bias, clamped, at 1.5 cm cells against a fine criss-cross mesh: constant-
    strain triangles on one-diagonal and unstructured meshes lock (here 1.43 and 1.26 times stiffer),
    node-smoothed strains do not (1.02 and 0.95; the issue's bound is 10 %)."""
    from yarnfit.mujoco.scenes import panel_mesh
    from yarnfit.validate.stretch import clamped_strip_stiffness

    # Shear-soft as a woven is (shear stiffness 1/40 of the weft's): on the bias its stiff yarns
    # run along the diagonals, the deformation a triangle cannot follow without stretching them.
    shell = ShellMaterial(thickness=H, s00=E, s01=0.1 * E, s11=0.8 * E, s22=E / 40, b00=1.0, b01=0.0, b11=1.0, b22=0.5)
    # 2 mm criss-cross cells: within 0.5 % of 1 mm ones.
    fine = clamped_strip_stiffness(shell, *grid_mesh(41, 26, 0.08, 0.05, crisscross=True), math.pi / 4)
    for points, triangles in (grid_mesh(7, 5, 0.08, 0.05),
                              panel_mesh(np.array([[-0.04, -0.025], [0.04, -0.025], [0.04, 0.025], [-0.04, 0.025]]),
                                         0.015)):
        locked = clamped_strip_stiffness(shell, points, triangles, math.pi / 4) / fine
        smoothed = clamped_strip_stiffness(shell, points, triangles, math.pi / 4, "node") / fine
        assert locked > 1.2 and abs(smoothed - 1) < 0.1, (locked, smoothed)


def test_clamped_strip_law_between_uniaxial_and_plane_strain():
    """Isotropic ν = 0.3: a long strip tends to E h, a short wide one to E h / (1 − ν²)."""
    from yarnfit.validate.stretch import clamped_strip_stiffness

    nu = 0.3
    c = E / (1 - nu**2)
    shell = ShellMaterial(thickness=H, s00=c, s01=nu * c, s11=c, s22=0.5 * (1 - nu) * c, b00=1.0, b01=0.0,
                          b11=1.0, b22=0.5)
    long = clamped_strip_stiffness(shell, *grid_mesh(201, 5, 1.0, 0.02), 0.0)
    short = clamped_strip_stiffness(shell, *grid_mesh(5, 401, 0.005, 0.5), 0.0)
    assert long == pytest.approx(E * H, rel=CLOSED_FORM_RTOL) and long > E * H
    assert short == pytest.approx(E * H / (1 - nu**2), rel=CLOSED_FORM_RTOL) and short < E * H / (1 - nu**2)


def test_no_poisson_strip_keeps_its_width_and_the_woven_narrows():
    flat = pull_strip(NO_POISSON, "8x5", "weft", quick=True, max_strain=0.05)
    assert np.abs(flat.compression_ratio - 1).max() < 1e-6
    woven = pull_strip(WOVEN, "8x5", "weft", quick=True, max_strain=0.05)
    assert np.all(np.diff(woven.compression_ratio) < 0) and woven.compression_ratio[-1] < 1


def test_bias_strips_of_a_woven_are_softer_than_weft_and_warp():
    """The paper's check (a): shear-soft wovens give way on the bias."""
    force = {d: pull_strip(WOVEN, "8x5", d, quick=True, max_strain=0.02).force_per_width_n_per_m[-1]
             for d in DIRECTIONS}
    assert force["bias"] < min(force["weft"], force["warp"])


# A woven whose shear stiffens one way only (a twill line): its two biases differ 11 times in a
# clamped strip's pull.
TWILL_LINE = ClothMaterial("twill-line", ShellMaterial(
    thickness=H, s00=FABRIC.s00, s01=FABRIC.s01, s11=FABRIC.s11, s22=FABRIC.s22, b00=FABRIC.b00, b01=0.0,
    b11=FABRIC.b11, b22=FABRIC.b22,
    nonlinear=RidgeMembrane(base=(FABRIC.s00, FABRIC.s01, FABRIC.s11, FABRIC.s22),
                            ridges=((0.0, 0.0, 1.0, 0.0, 10.0 * FABRIC.s22),))), DENSITY)
# The quick 9-vertex strip against the quasi-static shell strip (meshed along the yarns, extrapolated
# to a fine mesh): the clamped law's 6 % on the quick criss-cross mesh (§7) and the servo's lag.
QUASI_STATIC_RTOL = 0.1


def test_quasi_static_forces_reach_the_largest_measured_strain():
    """The quasi-static reference at measured strains that lag their levels (a servo leaves the
    last up to ~7 % short): the Poisson-free strip's closed form h s00 E λ at each, the last
    included (read off a strip pulled only to the level below, it was the lower level's force)."""
    strain = np.array([0.0019, 0.0048, 0.0093, 0.0186, 0.046, 0.0931])
    result = StripResult("8x5_weft", 0.08, 0.05, 0.0, strain, np.zeros(6), np.ones(6), np.ones(6, bool), 0.0, 1.0,
                         np.ones(6, bool))
    stretch = 1.0 + strain
    exact = H * E * 0.5 * (stretch**2 - 1.0) * stretch
    # Between load steps the closed form is read on straight lines: its curvature over 0.5 % steps
    # (measured 5e-4 at most).
    force, converged = quasi_static_forces(NO_POISSON.shell, result, quick=True)
    np.testing.assert_allclose(force, exact, rtol=5e-3)
    assert converged.all()


def test_quasi_static_forces_say_where_the_reference_did_not_converge(monkeypatch):
    """A level read between load steps that stopped unconverged is flagged (here every one: no
    Newton iteration allowed, from a guess that is not the equilibrium of a strip that narrows)."""
    import yarnfit.validate.shell_strip as shell_strip

    strain = np.array([0.002, 0.005])
    result = StripResult("8x5_bias", 0.08, 0.05, math.radians(45.0), strain, np.zeros(2), np.ones(2),
                         np.ones(2, bool), 0.0, 1.0, np.ones(2, bool))
    assert quasi_static_forces(TWILL_LINE.shell, result, quick=True)[1].all()
    monkeypatch.setattr(shell_strip, "MAX_NEWTON", 0)
    assert not quasi_static_forces(TWILL_LINE.shell, result, quick=True)[1].any()


def test_bias_strip_pulls_at_plus_45_degrees_from_the_weft():
    """The scene's bias strip is pulled at +45° from the weft (validate.DIRECTIONS, as the yarn
    scene's and the shell's own pulls): against the shell's quasi-static strip between the same
    clamps (yarnfit.validate.shell_strip) along +45°, not −45°."""
    result = pull_strip(TWILL_LINE, "8x5", "bias", quick=True, max_strain=0.005)
    length, width = result.length_m, result.width_m
    for angle, agrees in ((45.0, True), (-45.0, False)):
        strip = shell_strip_limit(TWILL_LINE.shell, angle, length, width, [0.002, 0.005], rows=6)
        for strain, force in zip(result.strain, result.force_per_width_n_per_m):
            quasi_static = np.interp(strain, [s.strain for s in strip.states], [s.force_n_per_m for s in strip.states])
            assert bool(abs(force / quasi_static - 1.0) <= QUASI_STATIC_RTOL) is agrees, (angle, force, quasi_static)


def entity_paths(path):
    return {chunk.entity_path for chunk in rr.chunk.RrdReader(path).stream()}


def test_run_writes_the_documented_recording_and_compares_a_reference(tmp_path):
    reference_csv = tmp_path / "measured.csv"
    # A "measurement" that is our own weft curve times 1.1, in N/cm and percent.
    ours = pull_strip(WOVEN, "8x5", "weft", quick=True, max_strain=0.05)
    rows = [f"weft,{100 * float(e)!r},{1.1 * float(f) / 100!r}" for e, f in zip(ours.strain, ours.force_per_width_n_per_m)]
    reference_csv.write_text("# made up from our own curve\ndirection,strain [%],force per width [N/cm]\n"
                             + "\n".join(rows) + "\n")
    reference = read_reference(reference_csv)
    path = tmp_path / "logs" / "woven" / "stretch.rrd"
    summary = run_stretch(WOVEN, quick=True, recording_path=path, reference=reference, max_strain=0.05).summary()
    assert set(summary["strips"]) == {f"8x5_{d}" for d in DIRECTIONS}
    # Every level against the shell's quasi-static strip between the same clamps (an independent
    # solve of the same energy): the test woven's strips at rest within the verdict's 10 % (measured
    # 0.1 % weft and warp, 4 % bias on the quick mesh).
    for strip in summary["strips"].values():
        assert all(strip["settled"])
        assert np.abs(np.array(strip["over_quasi_static"]) - 1.0).max() <= STRIPS_FOLLOW_SHELL_RTOL
    comparison = summary["reference"]["weft"]
    assert comparison["points"] == len(ours.strain)
    np.testing.assert_allclose(comparison["relative_difference"], 1 / 1.1 - 1, rtol=1e-9)
    paths = entity_paths(path)
    expected = {"/stretch/summary", "/stretch/plots/reference_force/weft"}
    expected |= {f"/stretch/8x5_{d}/cloth" for d in DIRECTIONS}
    expected |= {f"/stretch/plots/{kind}/8x5_{d}" for kind in ("force", "compression") for d in DIRECTIONS}
    assert expected <= paths


def test_strips_pulled_side_by_side_are_the_strips_pulled_one_at_a_time():
    """run_stretch pulls its strips on several threads: each strip's figures are those of the
    same strip pulled alone, bit for bit, and in the same order."""
    together = run_stretch(WOVEN, quick=True, max_strain=0.01).strips
    for strip in together:
        direction = strip.name.split("_")[1]
        alone = pull_strip(WOVEN, "8x5", direction, quick=True, max_strain=0.01)
        assert strip.name == alone.name
        for field in ("strain", "force_per_width_n_per_m", "compression_ratio", "settled", "stable"):
            np.testing.assert_array_equal(getattr(strip, field), getattr(alone, field))


def test_a_set_stop_event_interrupts_a_strip():
    stop = threading.Event()
    stop.set()
    with pytest.raises(KeyboardInterrupt):
        pull_strip(WOVEN, "8x5", "weft", quick=True, max_strain=0.01, stop=stop)


BAD_CSV = {
    "no units": ("direction,strain,force per width [N/m]\nweft,0.01,10\n", "column 'strain' has no unit"),
    "unknown unit": ("direction,strain [1],force per width [lbf/in]\nweft,0.01,10\n", r"has unit \[lbf/in\]"),
    "bad direction": ("direction,strain [1],force per width [N/m]\nwarpish,0.01,10\n", "direction 'warpish'"),
    "not a number": ("direction,strain [1],force per width [N/m]\nweft,0.01,ten\n", "'ten' is not a number"),
    "missing column": ("direction,strain [1]\nweft,0.01\n", "missing column 'force per width"),
    "empty": ("# nothing\n", "no header row"),
}


@pytest.mark.parametrize("case", sorted(BAD_CSV))
def test_bad_reference_files_fail_with_one_line(case, tmp_path):
    text, message = BAD_CSV[case]
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(ValueError, match=message) as error:
        read_reference(path)
    assert "\n" not in str(error.value) and str(path) in str(error.value)


def test_reference_units_are_converted_to_si(tmp_path):
    path = tmp_path / "units.csv"
    path.write_text("direction,strain [%],force per width [gf/cm],compression ratio [1]\n"
                    "warp,2,100,0.99\nwarp,1,50,\n")
    curve = read_reference(path).curves["warp"]
    np.testing.assert_allclose(curve.strain, [0.01, 0.02])
    np.testing.assert_allclose(curve.force_per_width, [50 * 0.980665, 100 * 0.980665])
    assert math.isnan(curve.compression_ratio[0]) and curve.compression_ratio[1] == 0.99


# Criss-cross against one diagonal per cell: the clamped law of a shear-soft woven's bias strip
# (shear 1/200 of the weft stiffness) on the full stretch mesh (25 vertices along) over a fine
# criss-cross mesh (97 along). Measured: criss-cross +2.1 % (+6.1 % on the quick 9), one diagonal
# 1.97 times (4.4 times on the quick mesh): locking, design notes §7.
CRISSCROSS_RTOL = 0.03
SHEAR_SOFT = ShellMaterial(thickness=H, s00=4.0e8, s01=5.0e7, s11=6.0e8, s22=2.0e6, b00=1.0, b01=0.0, b11=1.0,
                           b22=0.5)


def test_crisscross_cells_do_not_lock_on_the_bias():
    from yarnfit.validate.stretch import clamped_strip_stiffness

    bias = math.pi / 4
    fine = clamped_strip_stiffness(SHEAR_SOFT, *grid_mesh(97, 61, 0.08, 0.05, crisscross=True), bias)
    crisscross = clamped_strip_stiffness(SHEAR_SOFT, *grid_mesh(25, 16, 0.08, 0.05, crisscross=True), bias)
    one_diagonal = clamped_strip_stiffness(SHEAR_SOFT, *grid_mesh(25, 16, 0.08, 0.05), bias)
    assert crisscross == pytest.approx(fine, rel=CRISSCROSS_RTOL)
    assert one_diagonal > 1.5 * fine
    # Still the shell's own law along the fibres, where neither mesh locks.
    weft = [clamped_strip_stiffness(SHEAR_SOFT, *grid_mesh(9, 6, 0.08, 0.05, crisscross=c), 0.0) for c in (False, True)]
    assert weft[1] == pytest.approx(weft[0], rel=0.01)


def test_crisscross_mesh_counts_and_orientation():
    points, triangles = grid_mesh(4, 3, 0.3, 0.2, crisscross=True)
    assert points.shape == (4 * 3 + 3 * 2, 3) and triangles.shape == (4 * 3 * 2, 3)
    e1, e2 = points[triangles[:, 1]] - points[triangles[:, 0]], points[triangles[:, 2]] - points[triangles[:, 0]]
    area = 0.5 * np.cross(e1, e2)[:, 2]
    assert np.all(area > 0) and area.sum() == pytest.approx(0.3 * 0.2)  # counter-clockwise, covers the sheet
