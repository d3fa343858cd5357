"""Rerun recordings of shell fits: a real (small) fit of a cotton plain weave is recorded, read back
with ``rerun.chunk.RrdReader`` (no viewer, no network) and compared with what the fit computed —
every documented entity path and nothing else, one ``sample`` step per sample, the sample tilings
equal to the curved tiling's yarn strips, the shell curves through the fitted material's energy,
and the summary's units and R².
"""

import dataclasses
import functools
import json
import math
import re

import numpy as np
import pytest
import rerun as rr

import yarnfit.record
from yarnfit.engine import Residual
from yarnfit.engine.tiling import yarn_strips
from yarnfit.fabric import Fabric
from yarnfit.homogenize import tile_repeat
from yarnfit.fabric_fit import fit_fabric
from yarnfit.fibers import get_fiber
from yarnfit.record import EXCLUDED_COLOR, SAMPLE_TIMELINE, FitRecording
from yarnfit.samples import Family, SampleResult, design_size, family_deformation, identity_sample
from yarnfit.shell import GF_CM2_PER_CM

# Strips are stored as float32; positions are ~1e-3 m, so float32 round-off is ~1e-10 m.
POSITION_TOLERANCE = 1e-9  # m
# Curve points are float32 (relative round-off 6e-8 in p and W); the curve has a vertex at every
# sampled parameter, so interpolating there adds no error of its own beyond a slope times that.
CURVE_RTOL = 1e-6
# The summary prints R² to 6 significant digits (relative error ≤ 5e-6) ...
R2_RTOL = 1e-5
# ... and the engineering constants to 5 (≤ 5e-5).
CONSTANT_RTOL = 1e-4
# The 3 × 3 tiles in the order the recording stores them (i slowest).
TILES = [(i, j) for i in (-1, 0, 1) for j in (-1, 0, 1)]


@functools.lru_cache(maxsize=None)
def fitted():
    """A real fit, as small as the sample design allows (15 samples, ~10 s)."""
    fabric = Fabric(name="plain", fiber=get_fiber("cotton"), structure="plain", areal_density=0.2)
    return fit_fabric(fabric, samples=design_size(1), workers=1)


def record(fabric_fit, path, samples=True):
    """Record ``fabric_fit`` as the CLI does: start, every sample in design order, finish."""
    recording = FitRecording(fabric_fit.fabric.name, path)
    recording.start(fabric_fit.relaxed)
    if samples:
        for index, result in enumerate(fabric_fit.samples):
            recording.sample(index, fabric_fit.relaxed, result)
    recording.finish(fabric_fit)


def read_back(path, timeline=SAMPLE_TIMELINE):
    """``(reader, rows, timelines)``: ``rows[entity][component][step]`` the value logged at that
    step of ``timeline`` (``None`` for static data), ``timelines[entity]`` the timelines it has."""
    reader = rr.chunk.RrdReader(path)
    rows, timelines = {}, {}
    for chunk in reader.stream():
        batch = chunk.to_record_batch()
        names = batch.schema.names
        steps = batch.column(timeline).to_pylist() if timeline in names else [None] * batch.num_rows
        entity = rows.setdefault(chunk.entity_path.lstrip("/"), {})
        for name in (n for n in names if ":" in n):
            entity.setdefault(name, {}).update(zip(steps, batch.column(name).to_pylist()))
        timelines.setdefault(chunk.entity_path.lstrip("/"), set()).update(chunk.timeline_names)
    return reader, rows, timelines


def documented_paths(families):
    """Entity paths listed in the module docstring (the README quotes it), ``<family>`` expanded
    over ``families``."""
    templates = re.findall(r"``(fit(?:/[\w<>]+)*)``", yarnfit.record.__doc__)
    return {t.replace("<family>", f) for t in templates for f in (families if "<family>" in t else [""])}


def sampled_families(fabric_fit):
    return sorted({r.spec.family for r in fabric_fit.samples})


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """The fit, and its recording read back."""
    fabric_fit = fitted()
    path = tmp_path_factory.mktemp("fit") / "sub" / "plain-fit.rrd"
    global_before = rr.get_global_data_recording()
    record(fabric_fit, path)
    # The recording has a stream of its own: it neither creates nor replaces the global one.
    assert (rr.get_global_data_recording() is None) == (global_before is None)
    assert path.is_file() and path.stat().st_size > 0
    return fabric_fit, read_back(path)


def test_the_recording_holds_every_documented_path_and_nothing_else(recorded):
    fabric_fit, (reader, rows, timelines) = recorded
    assert [s.application_id for s in reader.recordings()] == ["yarnfit"]
    assert reader.blueprints(), "the recording should carry its viewer layout"
    assert rows["__properties"]["RecordingInfo:name"][None] == ["plain"]

    families = sampled_families(fabric_fit)
    documented = documented_paths(families)
    assert {"fit", "fit/relaxed/yarns", "fit/sample/yarns", "fit/sample/energy", "fit/sample/info",
            "fit/curves/shear/yarn", "fit/curves/shear/shell", "fit/summary"} <= documented
    # Every sample of this fit converges, so no family has excluded samples to draw.
    assert all(r.converged for r in fabric_fit.samples)
    excluded = {f"fit/curves/{f}/excluded" for f in families}
    recorded_paths = set(rows) - {"__properties"}
    assert recorded_paths == documented - excluded
    for entity in recorded_paths:
        temporal = entity.startswith("fit/sample/")
        assert (SAMPLE_TIMELINE in timelines[entity]) == temporal, entity


def test_each_sample_is_one_step_of_the_sample_timeline(recorded):
    fabric_fit, (_, rows, _) = recorded
    steps = list(range(len(fabric_fit.samples)))
    for entity, component in (("fit/sample/yarns", "LineStrips3D:strips"), ("fit/sample/energy", "Scalars:scalars"),
                              ("fit/sample/info", "TextDocument:text")):
        assert sorted(rows[entity][component]) == steps, entity
    for index, result in enumerate(fabric_fit.samples):
        assert rows["fit/sample/energy"]["Scalars:scalars"][index] == [pytest.approx(result.energy_density)]
        info = rows["fit/sample/info"]["TextDocument:text"][index][0]
        assert result.spec.family in info and "J/m²" in info and f"| iterations | {result.iterations} |" in info


def test_sample_tiles_are_the_curved_tilings_yarn_strips(recorded):
    fabric_fit, (_, rows, _) = recorded
    relaxed = fabric_fit.relaxed
    yarns = rows["fit/sample/yarns"]
    for index, result in enumerate(fabric_fit.samples):
        model = tile_repeat(relaxed, result.spec.I, result.spec.II).model
        strips = yarns["LineStrips3D:strips"][index]
        assert len(strips) == len(TILES) * model.n_rods
        # Tile (i, j) holds strips 3 (i + 1) + (j + 1) times the yarn count onwards; (0, 0) is the centre.
        for t, tile in enumerate(TILES):
            for k, want in enumerate(yarn_strips(model, result.position, tile)):
                np.testing.assert_allclose(np.array(strips[t * model.n_rods + k]), want, atol=POSITION_TOLERANCE,
                                           err_msg=f"sample {index}, tile {tile}, yarn {k}")
        assert yarns["LineStrips3D:radii"][index] == [pytest.approx(relaxed.radius)]
        colors = np.array(yarns["LineStrips3D:colors"][index]).reshape(len(TILES), model.n_rods)
        centre, neighbours = colors[TILES.index((0, 0))], np.delete(colors, TILES.index((0, 0)), axis=0)
        assert not set(centre) & set(neighbours.ravel())
        assert len(set(neighbours.ravel())) == 1  # all grey
        assert len(set(centre)) == model.n_rods  # one colour per yarn (fewer yarns than colours)

    relaxed_strips = rows["fit/relaxed/yarns"]["LineStrips3D:strips"][None]
    for got, want in zip(relaxed_strips, yarn_strips(relaxed.model, relaxed.state.node_position), strict=True):
        np.testing.assert_allclose(np.array(got), want, atol=POSITION_TOLERANCE)


def test_the_shell_curves_pass_through_the_fitted_energy_and_the_samples_are_plotted(recorded):
    fabric_fit, (_, rows, _) = recorded
    material = fabric_fit.material
    for family in sampled_families(fabric_fit):
        results = [r for r in fabric_fit.samples if r.spec.family == family]
        points = np.array(rows[f"fit/curves/{family}/yarn"]["Points2D:positions"][None])
        # Ū as the shell sees it: less the rest energy and the residual-stress terms.
        want = np.column_stack([[r.spec.parameter for r in results], fabric_fit.fit.shell_energy(results)])
        np.testing.assert_allclose(points, want, rtol=CURVE_RTOL, atol=CURVE_RTOL * np.abs(want[:, 1]).max())

        shell = rows[f"fit/curves/{family}/shell"]
        curve = np.array(shell["LineStrips2D:strips"][None][0])
        p, w = curve[:, 0], curve[:, 1]
        assert np.all(np.diff(p) > 0)
        assert p[0] <= min(0.0, want[:, 0].min()) and p[-1] >= max(0.0, want[:, 0].max())
        # At the family's largest sampled deformation, the curve is the fitted shell's energy.
        parameter = max((r.spec.parameter for r in results), key=abs)
        if Family(family).uniaxial_axis is not None:  # the shell's own free width
            expected = material.uniaxial_tension(Family(family).uniaxial_axis, 1.0 + parameter)[1]
        elif Family(family).uniaxial_angle is not None:  # the shell's own free strains on the bias
            pull = material.uniaxial_pull(Family(family).uniaxial_angle, 1.0 + parameter)
            expected = material.energy_density(pull.first_form, np.zeros((2, 2)))
        else:
            expected = material.energy_density(*family_deformation(family, parameter))
        assert np.interp(parameter, p, w) == pytest.approx(expected, rel=CURVE_RTOL)
        assert np.interp(0.0, p, w) == pytest.approx(0.0, abs=CURVE_RTOL * np.abs(w).max())

        # Drawn with y up (rerun's 2D views point y down) and scaled into a unit box.
        sx, sy, _ = shell["Transform3D:scale"][None][0]
        assert sx * np.abs(p).max() == pytest.approx(1.0, rel=CURVE_RTOL)
        assert sy < 0 and -sy * np.abs(np.append(w, want[:, 1])).max() == pytest.approx(1.0, rel=CURVE_RTOL)


def table_row(text, first_cell):
    """Cells of the markdown table row of ``text`` whose first cell is ``first_cell``."""
    for line in text.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if cells[0] == first_cell:
            return cells
    raise AssertionError(f"no row {first_cell!r} in\n{text}")


def test_the_summary_has_user_units_and_each_familys_fit_quality(recorded):
    fabric_fit, (_, rows, _) = recorded
    text = rows["fit/summary"]["TextDocument:text"][None][0]
    assert "gf·cm²/cm" in text and "N/m" in text
    engineering = fabric_fit.material.engineering()
    for key, label in (("bending_weft_nm", "bending weft"), ("bending_warp_nm", "bending warp"),
                       ("bending_bias_nm", "bending bias")):
        value, unit = table_row(text, label)[2].split()
        assert unit == "gf·cm²/cm"
        assert float(value) == pytest.approx(engineering[key] / GF_CM2_PER_CM, rel=CONSTANT_RTOL)
    for family in sampled_families(fabric_fit):
        quality = fabric_fit.fit.families[family]
        _, samples, r2, _ = table_row(text, family)
        assert int(samples) == quality["samples"]
        assert float(r2) == pytest.approx(quality["r2"], rel=R2_RTOL, abs=0.0)  # r2 may be −inf
    assert table_row(text, "model")[1] == fabric_fit.fit.model


def test_samples_that_did_not_converge_are_drawn_red_apart_from_the_fit(tmp_path):
    fabric_fit = fitted()
    failed = 1  # the weft stretch (design order: the undeformed sample, weft, warp, biaxial stretch, ...)
    samples = list(fabric_fit.samples)
    samples[failed] = dataclasses.replace(samples[failed], converged=False)
    flagged = dataclasses.replace(fabric_fit, samples=samples)
    path = tmp_path / "flagged.rrd"
    record(flagged, path, samples=False)

    _, rows, _ = read_back(path)
    family, spec = samples[failed].spec.family, samples[failed].spec
    assert [p for p in rows if p.endswith("/excluded")] == [f"fit/curves/{family}/excluded"]
    excluded = rows[f"fit/curves/{family}/excluded"]
    shell_energy = fabric_fit.fit.shell_energy
    np.testing.assert_allclose(excluded["Points2D:positions"][None],
                               [[spec.parameter, shell_energy([samples[failed]])[0]]], rtol=CURVE_RTOL)
    red = int.from_bytes(bytes([*EXCLUDED_COLOR, 255]), "big")  # rerun stores colours as 0xRRGGBBAA
    assert set(excluded["Points2D:colors"][None]) == {red}
    kept = [r for r in samples if r.spec.family == family and r.converged]
    np.testing.assert_allclose(rows[f"fit/curves/{family}/yarn"]["Points2D:positions"][None],
                               np.column_stack([[r.spec.parameter for r in kept], shell_energy(kept)]),
                               rtol=CURVE_RTOL, atol=CURVE_RTOL * np.abs(shell_energy(kept)).max())
    assert f"{len(samples)} ({len(samples) - 1} converged" in rows["fit/summary"]["TextDocument:text"][None][0]


def test_a_sample_without_a_state_is_written_as_nulls():
    # Every solve of the sample stepped beyond the mapped tiles: energy and residuals are NaN, and the
    # material file (strict JSON) says null.
    nan = math.nan
    result = SampleResult(spec=identity_sample(), energy_density=nan, converged=False,
                          residual=Residual(nan, nan, nan, nan), iterations=12, seconds=0.5,
                          position=np.zeros((1, 3)))
    written = json.loads(json.dumps(result.to_dict(), allow_nan=False))
    assert written["energy_density_j_m2"] is None and not written["converged"]
    assert set(written["residual"].values()) == {None}


def test_a_uniaxial_shell_curve_ends_where_the_width_collapses():
    """A membrane of Poisson ratio s01/s11 = 1.2 pulled along weft loses its width at a pulled Green
    strain of 1/2.4 (stretch 1.38): its uniaxial energy curve stops before, finite, instead of
    failing the fit's recording (polyester satin's weft did at 26 %)."""
    from yarnfit.shell import RidgeMembrane, ShellMaterial

    knit = ShellMaterial(thickness=1e-3, s00=2.0e6, s01=1.2e6, s11=1.0e6, s22=1.0e5, b00=1.0, b01=0.0, b11=1.0,
                         b22=1.0, nonlinear=RidgeMembrane((2.0e6, 1.2e6, 1.0e6, 1.0e5), ((1.0, 0.0, 0.0, 0.5, 1.0),)))
    p, energy = yarnfit.record.shell_curve(knit, Family.WEFT_UNIAXIAL, np.array([0.1, 0.5]))
    collapse = math.sqrt(1.0 + 2.0 / 2.4) - 1.0  # e = 1/(2 ν): the free width's Green strain reaches −½
    assert 0.1 in p and p.max() < collapse and len(energy) == len(p) and np.all(np.isfinite(energy))
    assert p.max() > 0.9 * collapse  # it ends at the collapse, not earlier
