"""`yarnfit catalogue` (yarnfit.catalogue): a labels table fitted and exported on a Dask cluster,
one row per failure, the table, a rerun from the cache, and an interrupted run that resumes."""

import csv
import json
import math
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from yarnfit.catalogue import TABLE_COLUMNS, Label, fabric_of, read_labels, run_catalogue
from yarnfit.fabric_fit import fit_fabric
from yarnfit.fibers import get_fiber
from yarnfit.material_file import MaterialFile
from yarnfit.samples import design_size
from yarnfit.tasks import DaskBackend, LocalPool

from test_tasks import checkout_env, default_sigint

# The smallest design (one magnitude per family and sign): the catalogue's machinery, not the fit,
# is under test here.
SAMPLES = design_size(1)  # the smallest design
# Two free-width pulls of a membrane even in the shear, mirrored: each balances its transverse
# stresses to 1e-9 (shell.UNIAXIAL_STRESS_RTOL), so their forces agree far inside this.
EVEN_PULL_RTOL = 1e-6
# The bound on a rerun of a finished catalogue (it loads the cached results only).
RERUN_SECONDS = 5.0
LABELS = """name,fibre,pattern,gsm,counts,yarn_spinning
plain-200,cotton,plain,200,25x25,
plain-150,cotton,plain,150,25x25,
no-such,unobtainium,plain,200,25x25,
bad-counts,cotton,plain,200,25by25,
jersey,cotton,jersey,180,,
plain-200,cotton,plain,210,25x25,
"""


def write_labels(folder: Path, text: str = LABELS) -> Path:
    path = folder / "labels.csv"
    path.write_text(text)
    return path


@pytest.mark.parametrize("text, message", [
    ("", "empty labels file"),
    ("name,fibre,pattern,gsm\nx,cotton,plain,200\n", r"lacks column\(s\) counts"),
    ("name,fibre,pattern,gsm,counts,colour\nx,cotton,plain,200,,red\n", r"unknown column\(s\) colour"),
    ("name,fibre,pattern,gsm,counts\n", "no fabric rows"),
])
def test_a_labels_file_that_cannot_be_read_is_one_line(text, message, tmp_path):
    with pytest.raises(ValueError, match=message):
        read_labels(write_labels(tmp_path, text))


@pytest.mark.parametrize("cells, message", [
    ({"name": "a b"}, "name 'a b'"),
    ({"fibre": "unobtainium"}, "unknown fibre"),
    ({"pattern": "lace"}, "pattern 'lace': unknown"),
    ({"gsm": "heavy"}, "gsm 'heavy': not a number"),
    ({"gsm": "-3"}, "positive areal density"),
    ({"counts": "25by25"}, "counts must look like 30x25"),
    ({"yarn_packing": "2"}, "yarn: "),
])
def test_a_bad_cell_names_itself(cells, message):
    good = {"name": "x", "fibre": "cotton", "pattern": "plain", "gsm": "200", "counts": "25x25"}
    with pytest.raises(ValueError, match=message):
        fabric_of(Label(2, {**good, **cells}))


def test_a_catalogue_on_a_dask_cluster(tmp_path):
    labels = write_labels(tmp_path)
    out = tmp_path / "out"
    with DaskBackend(workers=2) as cluster:
        run = run_catalogue(labels, out, cluster, samples=SAMPLES)
    status = {(e.label.line, e.label.name): (e.status, e.stage) for e in run.entries}
    assert status == {(2, "plain-200"): ("ok", ""), (3, "plain-150"): ("ok", ""), (4, "no-such"): ("failed", "input"),
                      (5, "bad-counts"): ("failed", "input"), (6, "jersey"): ("ok", ""),
                      (7, "plain-200"): ("failed", "input")}
    reasons = {e.label.line: e.reason for e in run.failed}
    assert "unknown fibre 'unobtainium'" in reasons[4] and "already on line 2" in reasons[7]
    for name in ("plain-200", "plain-150", "jersey"):
        material = json.loads((out / f"{name}.json").read_text())
        assert material["inputs"]["fabric"] == name
        assert (out / f"{name}-cloth.xml").read_text().startswith("<mujoco")
    # The table: one row per fabric in file order, the material files' own constants.
    with open(run.table_csv, newline="") as f:
        rows = list(csv.DictReader(f))
    assert [r["row"] for r in rows] == ["2", "3", "4", "5", "6", "7"] and list(rows[0]) == list(TABLE_COLUMNS)
    parquet = pq.read_table(run.table_parquet).to_pylist()
    assert [r["name"] for r in parquet] == [r["name"] for r in rows]
    jersey = json.loads((out / "jersey.json").read_text())["engineering"]
    assert parquet[4]["weft_stretch_n_per_m"] == jersey["weft_stretch_n_per_m"]
    # Unless told, the knit's membrane samples are loaded with its fibre's friction, the wovens' not.
    assert [r["sample_friction"] for r in parquet[:2]] == [0.0, 0.0]
    assert parquet[4]["sample_friction"] == get_fiber("cotton").friction > 0.0
    # ... and its shell is even in the shear: the same pull along either bias.
    shell = MaterialFile.read(out / "jersey.json").shell
    along, against = (shell.uniaxial_pull(angle, 1.05).force_n_per_m for angle in (math.pi / 4, -math.pi / 4))
    assert against == pytest.approx(along, rel=EVEN_PULL_RTOL)
    # A woven is pulled along both biases, a knit along one (fabric_fit.samples_both_biases).
    families = {name: [s["family"] for s in json.loads((out / f"{name}.json").read_text())["samples"]]
                for name in ("plain-200", "jersey")}
    assert len(families["plain-200"]) == design_size(1, both_biases=True) and len(families["jersey"]) == SAMPLES
    assert "negative_bias_uniaxial" in families["plain-200"] and "negative_bias_uniaxial" not in families["jersey"]
    assert float(rows[4]["weft_stretch_n_per_m"]) == jersey["weft_stretch_n_per_m"]
    assert parquet[2]["status"] == "failed" and parquet[2]["weft_stretch_n_per_m"] is None or \
        parquet[2]["weft_stretch_n_per_m"] != parquet[2]["weft_stretch_n_per_m"]
    assert not [p for p in out.rglob("*") if p.name.endswith(".part")]

    # A rerun loads the wanted results from the cache and runs nothing.
    ran = []
    start = time.perf_counter()
    with LocalPool(1) as pool:
        again = run_catalogue(labels, out, pool, samples=SAMPLES, on_done=lambda task, *_: ran.append(task.key))
    assert time.perf_counter() - start < RERUN_SECONDS
    assert sorted(k[0] for k in ran) == ["export"] * 3 + ["fit"] * 3
    assert [e.engineering for e in again.entries] == [e.engineering for e in run.entries]


def test_a_catalogue_with_friction_fits_what_yarnfit_fit_friction_fits(tmp_path):
    """With friction the membrane samples run as load paths (one task each) and are put back in the
    design's order: the material is the one `fit_fabric(friction=True)` makes, to the bit (the
    design's smallest paths are one sample long, the case a count of samples per task misreads)."""
    labels = write_labels(tmp_path, "name,fibre,pattern,gsm,counts\nplain-200,cotton,plain,200,25x25\n")
    with LocalPool(2) as pool:
        run = run_catalogue(labels, tmp_path / "out", pool, samples=SAMPLES, friction=True)
    entry, = run.entries
    assert entry.status == "ok", entry.reason
    assert entry.sample_friction == get_fiber("cotton").friction > 0.0
    with open(run.table_csv, newline="") as f:
        assert float(next(csv.DictReader(f))["sample_friction"]) == entry.sample_friction
    material = json.loads((tmp_path / "out" / "plain-200.json").read_text())
    fitted = fit_fabric(fabric_of(read_labels(labels)[0]), samples=SAMPLES, workers=2, friction=True)
    assert material["shell"] == MaterialFile.from_fit(fitted).data["shell"]
    assert material["fit"]["sample_friction"] == entry.sample_friction


def test_an_interrupted_catalogue_resumes(tmp_path):
    """SIGINT during the samples: exit 130 with one line, no half-written file, no worker left;
    the next run takes what the first finished from the cache and completes."""
    # Cotton twills: ~0.2 s per sample on one core, so at the first progress line with 5 tasks done
    # most are still to go (plain weaves had run past half of them once the solver was fast).
    labels = write_labels(tmp_path, "name,fibre,pattern,gsm,counts\n" + "".join(
        f"twill-{gsm},cotton,twill-2/1,{gsm},42x22\n" for gsm in (200, 220, 240, 260)))
    out = tmp_path / "out"
    command = [sys.executable, "-m", "yarnfit.cli", "catalogue", str(labels), "-o", str(out), "--samples",
               str(SAMPLES), "--workers", "2"]
    first = subprocess.Popen(command, stderr=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=checkout_env(),
                             preexec_fn=default_sigint)
    for line in first.stderr:  # off a terminal the progress line comes every 2 s
        match = re.search(r"\] (\d+)/(\d+) tasks", line)
        if match and int(match[1]) >= 5:  # some tasks done, most to go
            assert int(match[1]) < int(match[2]) // 2, "the run went too far before the interrupt"
            break
    else:
        pytest.fail("the catalogue ended before it was interrupted")
    workers = subprocess.run(["pgrep", "-P", str(first.pid)], capture_output=True, text=True).stdout.split()
    first.send_signal(signal.SIGINT)
    rest = first.stderr.read()
    assert first.wait(timeout=10) == 130
    assert rest.strip().splitlines()[-1] == "yarnfit catalogue: interrupted" and "Traceback" not in rest
    time.sleep(0.2)
    assert [w for w in workers if os.path.exists(f"/proc/{w}")] == []
    assert not [p for p in out.rglob("*") if p.name.endswith(".part")]
    before = {p.name: p.stat().st_mtime_ns for p in (out / ".cache").glob("*.pkl")}
    assert len(before) >= 5
    second = subprocess.run(command, capture_output=True, text=True, env=checkout_env(), timeout=600)
    assert second.returncode == 0, second.stderr
    assert "4 of 4 fabrics ok" in second.stdout
    # What the first run finished was loaded, not recomputed (a recomputed result is a new file).
    after = {p.name: p.stat().st_mtime_ns for p in (out / ".cache").glob("*.pkl")}
    assert {name: after[name] for name in before} == before
    # Per twill: its relaxation, its samples (a woven's design, both biases), its fit and export.
    assert len(after) == 4 * (1 + design_size(1, both_biases=True) + 2) > len(before)
