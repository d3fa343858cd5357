"""A fabric catalogue: labels in a CSV table, fitted, exported and validated, one row per fabric.

Input: a CSV file with a header row. Required columns ``name,fibre,pattern,gsm,counts`` (``gsm`` in
g/m², ``counts`` per cm as ``18x13``, empty for the structure's typical counts); optional
yarn-construction columns ``yarn_model``, ``yarn_spinning``, ``yarn_packing``, ``yarn_twist_deg``
(as the ``--yarn-*`` options of ``yarnfit fit``; empty cells take the defaults). Any other column
is refused (a misspelt column would otherwise be silently ignored).

Work: per fabric, a graph of tasks (:mod:`yarnfit.tasks`) — relax the repeat; solve the design's
samples, one task per group of :func:`yarnfit.homogenize.sample_groups` (each bend family and sign
as a path; loaded with friction (knits by default, as ``yarnfit fit``), each membrane family's
samples as one load path with the fibre's friction); fit the shell; export the MuJoCo scene; with
``validate``, run the validation scenes — on a local pool or a Dask cluster. Results are cached in
``DIR/.cache`` by a hash of every input and the yarnfit version, so a rerun, or a run after an
interrupted one, recomputes nothing it has.

Output ``DIR``:

- ``<name>.json``: the material file (``yarnfit fit``'s);
- ``<name>-cloth.xml``: the hanging-cloth scene (``yarnfit export --scene cloth``);
- ``logs/<name>/``: with ``validate``, the validation recordings and ``summary.json``;
- ``catalogue.csv`` and ``catalogue.parquet``: one row per fabric, its inputs, status (``ok`` or
  ``failed``, the stage and the one-line reason), engineering constants, the samples' friction, fit
  quality and verdicts (:data:`TABLE_COLUMNS`).

Every file is written whole or not at all (:func:`yarnfit.outputs.write_atomically`).
"""

from __future__ import annotations

import csv
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from .fabric import DEFAULT_COUNTS_PER_CM, Fabric, counts_from_label
from .checks import error_line
from .fabric_fit import (DEFAULT_SAMPLES, design_groups, fit_solved, loads_with_friction, relax_for_fit,
                         samples_both_biases, solve_design_group)
from .fibers import get_fiber
from .material_file import MaterialFile
from .outputs import write_atomically
from .samples import design_size, levels_for
from .tasks import Backend, Result, SkippedTask, Task, TaskCache, run_tasks
from .yarn import YarnConstruction

__all__ = ["CatalogueEntry", "CatalogueRun", "Label", "REQUIRED_COLUMNS", "TABLE_COLUMNS", "YARN_COLUMNS",
           "VALIDATION_SCENES", "fabric_of", "read_labels", "run_catalogue"]

REQUIRED_COLUMNS = ("name", "fibre", "pattern", "gsm", "counts")
# Optional columns and the YarnConstruction field each sets (the CLI's --yarn-* options).
YARN_COLUMNS = {"yarn_model": "model", "yarn_spinning": "spinning", "yarn_packing": "packing_fraction",
                "yarn_twist_deg": "twist_angle_deg"}
# The validation scenes a catalogue runs with --validate (quick meshes): the FAB strips and the two
# drapes a textile user compares (the yarn swatch and the body scene take minutes per fabric).
VALIDATION_SCENES = ("stretch", "sphere", "cusick")
# A file-safe fabric name: it names the fabric's files in DIR.
NAME_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*$")
# R² of a family says something only over a spread of magnitudes: with two samples (±κ of a bend,
# equal energies) its total variance is ~0 and R² reads −1e19 for a fit within 1 % (measured on a
# 16-sample plain weave). The table's minimum R² counts families of at least this many samples
# (the default 93-sample design has 4 to 9 per family); the worst family is ranked by relative RMS.
R2_MIN_SAMPLES = 4
ENGINEERING_KEYS = ("weft_stretch_n_per_m", "warp_stretch_n_per_m", "poisson_weft", "poisson_warp", "shear_n_per_m",
                    "bending_weft_nm", "bending_warp_nm", "bending_bias_nm")
# The table's columns, in order (inputs, outcome, engineering constants, fit quality, verdicts).
TABLE_COLUMNS = (("row", *REQUIRED_COLUMNS, *YARN_COLUMNS, "status", "stage", "reason", "material")
                 + ENGINEERING_KEYS + ("sample_friction", "fit_min_r2", "fit_worst_family", "fit_max_relative_rms",
                                       "verdicts_passed", "verdicts_failed"))


@dataclass(frozen=True)
class Label:
    """One row of the labels file: its line number (1 = the header) and its cells by column."""

    line: int
    cells: dict[str, str]

    @property
    def name(self) -> str:
        return self.cells.get("name", "").strip()


def read_labels(path: str | os.PathLike) -> list[Label]:
    """The rows of a labels CSV file (see the module docstring).

    Raises:
        ValueError: one line naming the file: unreadable, empty, a required column missing or
            an unknown column. A bad cell is the row's failure, not the file's (:func:`fabric_of`).
    """
    where = os.fspath(path)
    try:
        with open(where, newline="", encoding="utf-8-sig") as f:
            rows = list(csv.reader(f))
    except FileNotFoundError:
        raise ValueError(f"{where}: no such labels file") from None
    except (OSError, UnicodeDecodeError) as error:
        raise ValueError(f"{where}: cannot read the labels file: {error}") from None
    except csv.Error as error:
        raise ValueError(f"{where}: not a CSV file: {error}") from None
    rows = [(n, row) for n, row in enumerate(rows, start=1) if any(cell.strip() for cell in row)]
    if not rows:
        raise ValueError(f"{where}: empty labels file (expected a header row {','.join(REQUIRED_COLUMNS)})")
    _, header = rows[0]
    header = [h.strip().lower() for h in header]
    missing = [c for c in REQUIRED_COLUMNS if c not in header]
    if missing:
        raise ValueError(f"{where}: the header lacks column(s) {', '.join(missing)} "
                         f"(required: {','.join(REQUIRED_COLUMNS)})")
    unknown = [h for h in header if h not in REQUIRED_COLUMNS and h not in YARN_COLUMNS]
    if unknown:
        raise ValueError(f"{where}: unknown column(s) {', '.join(unknown)} (columns: {', '.join(REQUIRED_COLUMNS)}, "
                         f"optional {', '.join(YARN_COLUMNS)})")
    if len(set(header)) != len(header):
        raise ValueError(f"{where}: a column appears twice in the header")
    labels = []
    for line, row in rows[1:]:
        cells = {column: (row[i].strip() if i < len(row) else "") for i, column in enumerate(header)}
        if len(row) > len(header) and any(cell.strip() for cell in row[len(header):]):
            cells["_extra"] = f"{len(row)} cells for {len(header)} columns"
        labels.append(Label(line, cells))
    if not labels:
        raise ValueError(f"{where}: no fabric rows below the header")
    return labels


def fabric_of(label: Label) -> Fabric:
    """The :class:`~yarnfit.fabric.Fabric` a row describes.

    Raises:
        ValueError: one line naming the bad cell.
    """
    cells = label.cells
    if "_extra" in cells:
        raise ValueError(f"line {label.line}: {cells['_extra']}")
    name = label.name
    if not NAME_PATTERN.match(name):
        raise ValueError(f"name {name!r}: use letters, digits, '.', '_' and '-' (it names the fabric's files)")
    if not cells["fibre"]:
        raise ValueError("fibre: empty")
    fiber = get_fiber(cells["fibre"])
    pattern = cells["pattern"]
    if pattern not in DEFAULT_COUNTS_PER_CM:
        raise ValueError(f"pattern {pattern!r}: unknown (patterns: {', '.join(DEFAULT_COUNTS_PER_CM)})")
    try:
        gsm = float(cells["gsm"])
    except ValueError:
        raise ValueError(f"gsm {cells['gsm']!r}: not a number of g/m²") from None
    if not (math.isfinite(gsm) and gsm > 0):
        raise ValueError(f"gsm {cells['gsm']!r}: must be a positive areal density in g/m²")
    counts = counts_from_label(cells["counts"]) if cells["counts"] else None
    yarn = {}
    for column, key in YARN_COLUMNS.items():
        text = cells.get(column, "")
        if not text:
            continue
        if key in ("packing_fraction", "twist_angle_deg"):
            try:
                yarn[key] = float(text)
            except ValueError:
                raise ValueError(f"{column} {text!r}: not a number") from None
        else:
            yarn[key] = text
    try:
        construction = YarnConstruction(**yarn)
    except ValueError as error:
        raise ValueError(f"yarn: {error}") from None
    return Fabric(name=name, fiber=fiber, structure=pattern, areal_density=gsm * 1e-3, counts=counts,
                  yarn=construction)


@dataclass(frozen=True)
class CatalogueEntry:
    """One fabric's outcome.

    Attributes:
        label: its row.
        status: ``"ok"`` or ``"failed"``.
        stage: where it failed (``input``, ``relax``, ``samples``, ``fit``, ``export``, ``validate``),
            empty when ok.
        reason: the failure in one line, empty when ok.
        material: the material file written (path), or None.
        engineering: the small-strain engineering constants (SI, the material file's keys).
        sample_friction: the friction coefficient its membrane samples were loaded with (0: the
            paper's frictionless samples; NaN without a fit).
        fit_min_r2: the least R² of a family of at least :data:`R2_MIN_SAMPLES` samples (NaN if none);
        fit_worst_family, fit_max_relative_rms: the family with the largest relative RMS error, and it.
        verdicts_passed: validation checks passed (None without validation);
        verdicts_failed: the checks that missed their criterion.
    """

    label: Label
    status: str
    stage: str = ""
    reason: str = ""
    material: str | None = None
    engineering: dict[str, float] = field(default_factory=dict)
    sample_friction: float = math.nan
    fit_min_r2: float = math.nan
    fit_worst_family: str = ""
    fit_max_relative_rms: float = math.nan
    verdicts_passed: int | None = None
    verdicts_failed: tuple[str, ...] = ()

    def table_row(self) -> dict:
        """The entry as one row of :data:`TABLE_COLUMNS` (str, float, int or None)."""
        row = {"row": self.label.line}
        row.update({c: self.label.cells.get(c, "") for c in (*REQUIRED_COLUMNS, *YARN_COLUMNS)})
        row.update({"status": self.status, "stage": self.stage, "reason": self.reason, "material": self.material or ""})
        row.update({k: self.engineering.get(k, math.nan) for k in ENGINEERING_KEYS})
        row.update({"sample_friction": self.sample_friction, "fit_min_r2": self.fit_min_r2,
                    "fit_worst_family": self.fit_worst_family, "fit_max_relative_rms": self.fit_max_relative_rms,
                    "verdicts_passed": self.verdicts_passed, "verdicts_failed": ";".join(self.verdicts_failed)})
        return row


@dataclass(frozen=True)
class CatalogueRun:
    """A catalogue's outcome: an entry per row (in file order) and the table files written."""

    entries: list[CatalogueEntry]
    table_csv: Path
    table_parquet: Path

    @property
    def failed(self) -> list[CatalogueEntry]:
        return [e for e in self.entries if e.status != "ok"]


# -- tasks (module-level: they are pickled to the workers) ----------------------------------------


def fit_task(fabric: Fabric, relaxed, model: str, friction: bool, layout: tuple[tuple[int, ...], ...],
             *outcomes) -> dict:
    """The material file's contents of the shell fitted to the design's samples: ``outcomes[j]``
    carries the samples ``layout[j]`` of the design (one sample, or a path's list), loaded
    with the fibre's friction if ``friction``."""
    results: list = [None] * sum(len(indices) for indices in layout)
    for indices, outcome in zip(layout, outcomes, strict=True):
        for i, sample in zip(indices, outcome if isinstance(outcome, list) else [outcome], strict=True):
            results[i] = sample
    return MaterialFile.from_fit(fit_solved(fabric, relaxed, results, model,
                                            sample_friction=relaxed.fiber.friction if friction else 0.0)).data


def export_task(material_data: dict) -> str:
    """The ``cloth`` scene of a material (``yarnfit export --scene cloth``) as MJCF text, checked to
    compile."""
    import mujoco

    from .mujoco.scenes import ClothMaterial, build_scene, compile_quietly, export_options, scene_mjcf

    material = ClothMaterial.from_file(MaterialFile(material_data))
    text = scene_mjcf(build_scene(material, "cloth", **export_options("cloth")))
    compile_quietly(mujoco.MjSpec.from_string(text))
    return text


def validate_task(material_path: str, scenes: tuple[str, ...], quick: bool, logs: str, material_data: dict) -> dict:
    """The validation suite's summary (``yarnfit validate``) of the material file at
    ``material_path`` (written by the parent from ``material_data``, the fit task's result, before
    this task starts; taking it makes the fit this task's dependency and part of its cache key);
    recordings go to ``logs``. A cluster's workers must see the catalogue's directory."""
    from .validate.suite import run_suite

    summary, _ = run_suite(material_path, scenes, quick=quick, logs=logs)
    return summary


# -- the run --------------------------------------------------------------------------------------


def run_catalogue(
    labels_path: str | os.PathLike,
    out_dir: str | os.PathLike,
    backend: Backend,
    *,
    samples: int = DEFAULT_SAMPLES,
    model: str = "full",
    validate: bool = False,
    scenes: tuple[str, ...] = VALIDATION_SCENES,
    quick: bool = True,
    on_done: Callable[[Task, object, int, int], None] | None = None,
    friction: bool | None = None,
) -> CatalogueRun:
    """Fit, export and (with ``validate``) validate every row of the labels file into ``out_dir``
    (see the module docstring) on ``backend``; ``on_done`` as for :func:`yarnfit.tasks.run_tasks`.
    With ``friction`` the membrane samples are loaded from rest with the fibre's friction (as
    ``yarnfit fit --friction``), one task per load path; ``None``: each fabric as its structure
    asks (:func:`yarnfit.fabric_fit.loads_with_friction`: knits loaded, wovens not).

    A row's failure (bad input, or any stage) is its entry's; the other rows still complete.

    Raises:
        ValueError: a labels file that cannot be read (:func:`read_labels`) or a bad option.
        KeyboardInterrupt: after the backend's work is stopped; finished outputs stay (cached
            and written), nothing is half-written.
    """
    labels = read_labels(labels_path)
    levels_for(samples)  # validates the count
    if model not in ("full", "paper"):
        raise ValueError(f"model must be 'full' or 'paper', got {model!r}")
    out = Path(out_dir)
    entries: dict[int, CatalogueEntry] = {}
    fabrics: dict[int, Fabric] = {}
    seen: dict[str, int] = {}
    for i, label in enumerate(labels):
        try:
            fabric = fabric_of(label)
            if label.name in seen:
                raise ValueError(f"name {label.name!r} already on line {seen[label.name]}")
        except ValueError as error:
            entries[i] = CatalogueEntry(label, "failed", "input", error_line(error))
            continue
        seen[label.name] = label.line
        fabrics[i] = fabric

    tasks, wanted = [], []
    for i, fabric in fabrics.items():
        name = fabric.name
        loaded = loads_with_friction(fabric) if friction is None else friction
        both_biases = samples_both_biases(fabric)
        count = design_size(levels_for(samples), both_biases)
        # Each sample task's design indices: one sample alone, a bend path, or (loaded) a load path.
        layout = tuple(design_groups(samples, loaded, both_biases))
        tasks.append(Task(("relax", i), relax_for_fit, (fabric,), cost=3.0, label=f"{name}: relax"))
        for j, indices in enumerate(layout):
            # A path: a few samples' worth of solves or more, so it starts before the single samples.
            what = (f"sample {indices[0] + 1}/{count}" if len(indices) == 1 else
                    f"path of samples {', '.join(str(k + 1) for k in indices)}/{count}")
            tasks.append(Task(("samples", i, j), solve_design_group,
                              (Result(("relax", i)), samples, indices, loaded, both_biases),
                              cost=1.0 + len(indices), label=f"{name}: {what}"))
        results = tuple(Result(("samples", i, j)) for j in range(len(layout)))
        tasks.append(Task(("fit", i), fit_task, (fabric, Result(("relax", i)), model, loaded, layout, *results),
                          cost=1.0, label=f"{name}: fit"))
        tasks.append(Task(("export", i), export_task, (Result(("fit", i)),), label=f"{name}: export"))
        wanted += [("fit", i), ("export", i)]
        if validate:
            material_path = str((out / f"{name}.json").resolve())
            tasks.append(Task(("validate", i), validate_task,
                              (material_path, tuple(scenes), quick, str((out / "logs").resolve()), Result(("fit", i))),
                              label=f"{name}: validate"))
            wanted.append(("validate", i))

    def done(task, outcome, finished, total):
        # Files are written here, in the parent, as each stage finishes: before any task that
        # reads them is submitted (a dependent is released only after this returns).
        stage, i = task.key[0], task.key[1]
        if not isinstance(outcome, BaseException):
            name = fabrics[i].name
            if stage == "fit":
                MaterialFile(outcome).write(out / f"{name}.json")
            elif stage == "export":
                write_atomically(out / f"{name}-cloth.xml", outcome)
        if on_done is not None:
            on_done(task, outcome, finished, total)

    outcomes = run_tasks(tasks, backend, cache=TaskCache(out / ".cache"), on_done=done, wanted=wanted)
    for i, fabric in fabrics.items():
        entries[i] = _entry(labels[i], fabric, i, outcomes, out, validate)
    ordered = [entries[i] for i in range(len(labels))]
    table_csv, table_parquet = write_table(ordered, out)
    return CatalogueRun(ordered, table_csv, table_parquet)


def _entry(label: Label, fabric: Fabric, i: int, outcomes: dict, out: Path, validate: bool) -> CatalogueEntry:
    stages = ["fit", "export"] + (["validate"] if validate else [])
    for stage in stages:
        outcome = outcomes.get((stage, i))
        if isinstance(outcome, BaseException):
            where, cause = stage, outcome
            if isinstance(outcome, SkippedTask):
                # The stage that failed first: relax, a sample, or the fit.
                where, cause = next(((k[0], v) for k, v in outcomes.items() if k[1] == i
                                     and isinstance(v, BaseException) and not isinstance(v, SkippedTask)),
                                    (stage, outcome))
            material = str(out / f"{fabric.name}.json") if stage != "fit" else None
            return CatalogueEntry(label, "failed", where, error_line(cause), material, **_fit_columns(outcomes, i))
    entry = dict(_fit_columns(outcomes, i))
    if validate:
        verdicts = outcomes[("validate", i)].get("verdicts", [])
        entry["verdicts_passed"] = sum(1 for v in verdicts if v.get("passed") is True)
        entry["verdicts_failed"] = tuple(v["check"] for v in verdicts if v.get("passed") is False)
    return CatalogueEntry(label, "ok", material=str(out / f"{fabric.name}.json"), **entry)


def _fit_columns(outcomes: dict, i: int) -> dict:
    data = outcomes.get(("fit", i))
    if not isinstance(data, dict):
        return {}
    families = data["fit"]["families"]
    rms = {name: f["relative_rms"] for name, f in families.items() if f.get("relative_rms") is not None}
    worst = max(rms, key=rms.get) if rms else ""
    r2 = [f["r2"] for f in families.values() if f.get("r2") is not None and f.get("samples", 0) >= R2_MIN_SAMPLES]
    return {"engineering": {k: float(data["engineering"][k]) for k in ENGINEERING_KEYS if k in data["engineering"]},
            "sample_friction": float(data["fit"].get("sample_friction", 0.0)),
            "fit_min_r2": float(min(r2)) if r2 else math.nan, "fit_worst_family": worst,
            "fit_max_relative_rms": float(rms[worst]) if worst else math.nan}


def write_table(entries: list[CatalogueEntry], out: Path) -> tuple[Path, Path]:
    """``catalogue.csv`` and ``catalogue.parquet`` in ``out``, one row per entry
    (:data:`TABLE_COLUMNS`), each written whole or not at all."""
    import io

    import pyarrow as pa
    import pyarrow.parquet as pq

    rows = [e.table_row() for e in entries]
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=TABLE_COLUMNS, lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: ("" if v is None or (isinstance(v, float) and math.isnan(v)) else v)
                         for k, v in row.items()})
    table_csv = write_atomically(out / "catalogue.csv", text.getvalue())
    types = {"row": pa.int64(), "verdicts_passed": pa.int64(), "sample_friction": pa.float64(),
             "fit_min_r2": pa.float64(), "fit_max_relative_rms": pa.float64(),
             **{k: pa.float64() for k in ENGINEERING_KEYS}}
    schema = pa.schema([(c, types.get(c, pa.string())) for c in TABLE_COLUMNS])
    table = pa.Table.from_pylist(rows, schema=schema)
    sink = pa.BufferOutputStream()
    pq.write_table(table, sink)
    table_parquet = write_atomically(out / "catalogue.parquet", sink.getvalue().to_pybytes())
    return table_csv, table_parquet
