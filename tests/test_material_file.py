"""The material file (yarnfit.material_file): what `yarnfit fit` writes reads back, the relaxed
repeat it keeps rebuilds the fitted one, and files it cannot use are refused in one line."""

from __future__ import annotations

import functools
import json

import numpy as np
import pytest

import yarnfit
from yarnfit.fabric import Fabric
from yarnfit.fabric_fit import fit_fabric
from yarnfit.material_file import IncompatibleMaterial, MaterialFile
from yarnfit.samples import design_size
from yarnfit.fibers import get_fiber
from yarnfit.validate.swatch import run_yarn

# The kept repeat starts at its own equilibrium: positions come back to round-off of the solve's
# last correction (force residual 1e-8 of the scale on a stiff contact network: far below 1e-9 r).
REPEAT_POSITION_RTOL = 1e-9
# Relaxing the kept repeat again starts at its equilibrium, but without the contact multipliers
# (they are not kept): their updates take ~15 iterations (plain weave: 14, against 16 for the
# relaxation from the pattern; a knit's takes hundreds). Twice that is a failed rebuild.
REBUILD_ITERATIONS = 30


@functools.lru_cache(maxsize=None)
def fitted():
    fabric = Fabric(name="plain", fiber=get_fiber("cotton"), structure="plain", areal_density=0.2,
                    counts=(2500.0, 2500.0))
    return fit_fabric(fabric, samples=design_size(1), workers=1)


def test_what_fit_writes_reads_back(tmp_path):
    fit = fitted()
    file = MaterialFile.read(fit.write(tmp_path / "plain.json"))
    file.check_version()
    assert file.shell == fit.material
    assert file.fabric() == fit.fabric
    assert file.name == "plain"
    assert file.areal_density() == (pytest.approx(0.2), "inputs.areal_density_kg_m2")
    assert MaterialFile.read(json.loads((tmp_path / "plain.json").read_text())).shell == fit.material


def test_the_kept_relaxed_repeat_is_the_fitted_one(tmp_path):
    fit = fitted()
    relaxed = MaterialFile.read(fit.write(tmp_path / "plain.json")).relaxed_repeat()
    assert relaxed.converged and relaxed.valid
    assert relaxed.iterations <= REBUILD_ITERATIONS
    assert relaxed.radius == fit.relaxed.radius
    np.testing.assert_array_equal(relaxed.repeat_size, fit.relaxed.repeat_size)
    np.testing.assert_allclose(relaxed.state.node_position, fit.relaxed.state.node_position, rtol=0.0,
                               atol=REPEAT_POSITION_RTOL * fit.relaxed.radius)
    # Rest lengths are the relaxed edge lengths: off by at most the two ends' position errors.
    np.testing.assert_allclose(relaxed.model.edge_rest_length, fit.relaxed.model.edge_rest_length, rtol=0.0,
                               atol=2 * REPEAT_POSITION_RTOL * fit.relaxed.radius)


def test_a_file_without_a_relaxed_repeat_relaxes_again_with_a_note(tmp_path):
    data = fitted().to_dict()
    del data["relaxed_repeat"]
    assert MaterialFile.read(data).relaxed_repeat() is None
    notes = []
    out = run_yarn(data, quick=True, recording_path=False, directions=("weft",),
                   size={"gauge": 1.0, "width": 1.0, "clamp": 0.5}, progress=notes.append)
    assert "keeps no relaxed repeat" in notes[0] and "relaxing plain again" in notes[0]
    assert out.relaxation["converged"]


def test_files_this_version_cannot_use_are_refused(tmp_path):
    data = fitted().to_dict()
    with pytest.raises(IncompatibleMaterial, match="written by yarnfit '0.0.1'"):
        MaterialFile.read({**data, "yarnfit_version": "0.0.1"}).check_version()
    with pytest.raises(IncompatibleMaterial, match="missing keys inputs, engineering"):
        MaterialFile.read({"yarnfit_version": yarnfit.__version__, "shell": data["shell"]}).check_version()
    listed = tmp_path / "list.json"
    listed.write_text("[1, 2]")
    with pytest.raises(ValueError, match=r"list\.json: expected a JSON object .* got a list"):
        MaterialFile.read(listed)
    with pytest.raises(ValueError, match="missing key 'shell'"):
        MaterialFile.read({"inputs": {}}).shell
    with pytest.raises(ValueError, match="relaxed_repeat must be an object with the key 'pyp'"):
        MaterialFile.read({**data, "relaxed_repeat": "plain.pyp"}).relaxed_repeat()


def test_an_earlier_membrane_model_is_refused_and_its_linear_fit_still_reads():
    """A file whose ``shell.nonlinear`` is an earlier yarnfit's ``green-polynomial`` block: its
    shell is refused with what to do, and ``linear_shell`` (what ``export --linear`` reads) is
    its linear fit, the nonlinear block not read."""
    data = json.loads(json.dumps(fitted().to_dict()))
    data["shell"]["nonlinear"] = {"model": "green-polynomial", "stress_terms_pa": {}, "stiffening_strain": {},
                                  "compression_pa": {}}
    old = MaterialFile.read(data)
    with pytest.raises(ValueError, match="no longer supported: fit the fabric again .* or export --linear"):
        old.shell
    assert old.linear_shell == fitted().fit.linear
