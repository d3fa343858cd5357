"""Figures and tables of a fitted material and of its validation, in the units a textile lab uses.

Every figure is written as PNG (raster, :data:`PNG_DPI`) and SVG (vector, text as paths so that it
renders without the fonts), drawn with matplotlib's Agg and SVG canvases: no display and no pyplot
state are needed, so the functions run in a terminal, a worker process or CI. Beside each curve
figure a CSV table (UTF-8, one header row, each numeric column's unit in brackets as in
``validation/reference/*.csv``) holds the numbers the figure plots.

:func:`fit_figures` (from a ``yarnfit fit`` material file), in ``out_dir``, ``<fabric>`` the
fabric's name made safe for a file name (:func:`file_stem`):

- ``<fabric>-fit-<family>.png|svg|csv`` for every sample family with samples: the yarn-level
  samples' energy density against the fitted shell's along the same deformations;
- ``<fabric>-tension.png|svg|csv``: the shell's uniaxial force–strain curve per direction;
- ``<fabric>-bending.png|svg|csv``: the shell's bending moment against curvature per direction,
  and ``<fabric>-bending-rigidity.csv`` the rigidities themselves.

:func:`validation_figures` (from ``yarnfit validate``'s ``summary.json``):

- ``<fabric>-stretch-<direction>.png|svg|csv`` for every direction with a curve: the shell strips
  pulled in MuJoCo, the yarn-level swatch, a measured reference curve, and the shell's law.

Units. Strains are engineering strains λ − 1 in % (shear: ``I₁₂``, twice the Green shear strain, in
%), forces per width in N/cm, bending rigidities in gf·cm²/cm and moments per width in gf·cm/cm
(the KES-F units), curvatures in 1/m on the fit figures (the samples' own) and 1/cm on the bending
figure (so its slope is the rigidity in gf·cm²/cm), energy densities in J/m² of undeformed fabric.
"""

from __future__ import annotations

import csv
import math
import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from .fit import shell_energy_of
from .jsonfile import read_json
from .material_file import MaterialFile
from .record import EXCLUDED_COLOR, SAMPLE_COLOR, SHELL_COLOR, shell_curve
from .samples import FAMILIES, Group, SampleResult
from .shell import GF_CM2_PER_CM, ShellMaterial
from .validate import DIRECTIONS, PULL_DIRECTIONS
from .validate.reference import FORCE_UNITS, Reference, read_reference

__all__ = [
    "CM_PER_M",
    "N_PER_M_IN_N_PER_CM",
    "PERCENT",
    "Series",
    "file_stem",
    "fit_figures",
    "output_directory",
    "validation_figures",
]

# -- units: a value in SI divided by the factor is the value in the textile unit -----------------

# N/m in one N/cm: 1 N/cm = 1 N / 0.01 m = 100 N/m (the factor a reference CSV's [N/cm] column is
# read with), so a force per width in N/m ÷ 100 is in N/cm.
N_PER_M_IN_N_PER_CM = FORCE_UNITS["N/cm"]
# Bending rigidity: N·m in one gf·cm²/cm is shell.GF_CM2_PER_CM = 1 gf × 1 cm = 9.80665e-3 N ×
# 1e-2 m = 9.80665e-5 N·m (gf: 1 g under standard gravity 9.80665 m/s²), the factor `yarnfit fit`
# prints its rigidities with; N·m ÷ 9.80665e-5 = N·m × 10197.16 is in gf·cm²/cm. A moment per width
# in gf·cm/cm (= gf) is then the rigidity in gf·cm²/cm times the curvature in 1/cm.
# cm in one m: a length in m × 100 is in cm, a curvature in 1/m ÷ 100 in 1/cm.
CM_PER_M = 100.0
# A strain (dimensionless) × 100 is in %.
PERCENT = 100.0

# -- what is drawn ----------------------------------------------------------------------------------

# The directions of the engineering constants' bending rigidities (``bending_<direction>_nm``):
# the bend's curvature along weft, along warp, and at 45° (bias).
BENDING_DIRECTIONS = ("weft", "warp", "bias")
# Points of the shell's uniaxial and bending curves: the uniaxial law is a quartic in the strain at
# most (the stiffening membrane), smooth to the eye at this density, and each point is one small
# Newton solve (ShellMaterial.uniaxial_pull, ~1 ms).
CURVE_POINTS = 101
# Largest strain of the tension curves when the material file keeps no fitted stretch range: the
# validation suite's largest strain level (yarnfit.validate.stretch.STRAIN_LEVELS, not imported:
# it loads MuJoCo).
DEFAULT_STRETCH_RANGE = 0.10
# Largest curvature of the bending curves (1/cm) when the file keeps no fitted curvature range:
# the ±2.5 cm⁻¹ of the KES-FB2 pure-bending tester, the instrument gf·cm²/cm comes from.
DEFAULT_CURVATURE_RANGE_PER_CM = 2.5
# Figure size (inches) and PNG resolution: a column-wide figure, sharp on a screen and in print.
FIGURE_INCHES = (6.4, 4.4)
PNG_DPI = 150
# One colour per direction (matplotlib's default cycle), the same in every figure.
DIRECTION_COLORS = {"weft": "tab:blue", "warp": "tab:orange", "bias": "tab:green", "other bias": "tab:red"}
# The stretch figures: the shell strips in blues and purples (line and dots, one colour per strip
# size), the yarn-level swatch orange (dashed, squares), a measurement black (diamonds, no line: the
# lab's points as they are), the shell's law a thin grey line under everything.
STRIP_COLORS = ("tab:blue", "tab:cyan", "tab:purple", "tab:olive")
STRIP_STYLE = {"marker": "o", "ls": "-", "lw": 1.3, "ms": 4}
YARN_STYLE = {"color": "tab:orange", "marker": "s", "ls": "--", "lw": 1.0, "ms": 5}
YARN_MIDDLE_STYLE = {"color": "tab:orange", "marker": "s", "mfc": "none", "ls": ":", "lw": 1.0, "ms": 5}
MEASURED_STYLE = {"color": "black", "marker": "D", "ls": "none", "ms": 5}
LAW_STYLE = {"color": "0.45", "ls": "-", "lw": 0.9, "zorder": 1}
# The fit figures use the Rerun recording's colours (yarnfit.record: samples blue, samples left out
# red, the shell's curve near-black), 8-bit RGB there; matplotlib takes fractions of this.
_RGB = 255.0


# -- typed results ------------------------------------------------------------------------------


@dataclass(frozen=True)
class Series:
    """One plotted set of points of a long-format table: ``label`` (the legend entry and the CSV's
    ``series`` column), ``x (n,)`` and ``y (n,)`` in the figure's units, ``extra`` further columns
    by header (each ``(n,)``), ``ok (n,)``: the point converged (or came to rest), ``None`` for
    a curve that has no such notion; ``style``: how it is drawn (matplotlib ``plot`` keywords)."""

    label: str
    x: np.ndarray
    y: np.ndarray
    extra: dict[str, np.ndarray] = field(default_factory=dict)
    ok: np.ndarray | None = None
    style: dict = field(default_factory=dict)


# -- the fit --------------------------------------------------------------------------------------


def fit_figures(material: str | os.PathLike | Mapping | MaterialFile, out_dir: str | os.PathLike) -> list[Path]:
    """Figures and tables of a fitted material, written to ``out_dir`` (created if missing).

    Args:
        material: a ``yarnfit fit`` material file (path, its decoded JSON, or a
            :class:`~yarnfit.material_file.MaterialFile`) that keeps its yarn-level samples.
        out_dir: the directory to write to.

    Written (``<fabric>`` = :func:`file_stem` of the fabric's name):

    - ``<fabric>-fit-<family>.png``, ``.svg``, ``.csv`` per sample family with samples: the
      yarn-level samples' energy density (points; those that did not converge, left out of the fit,
      as red crosses) against the fitted shell's (line, ``yarnfit.record.shell_curve``: the
      family's deformation at each parameter; for the uniaxial families the shell's own free
      width), energy density in J/m² against the family's parameter (strain in %, curvature in
      1/m). The samples are drawn as the shell sees them: their Ū less the rest energy and
      residual-stress terms the fit took out (:func:`yarnfit.fit.shell_energy_of`). CSV columns:
      ``series`` ("yarn level", "yarn level, not converged", "shell"), the parameter, ``energy
      density [J/m^2]`` (as plotted), ``energy density as solved [J/m^2]`` (the file's Ū; samples
      only) and ``converged`` (samples only).
    - ``<fabric>-tension.png``, ``.svg``, ``.csv``: the shell's uniaxial tension in weft, warp and
      both biases (+45° and −45°, "other bias"), every other stress free
      (:meth:`ShellMaterial.uniaxial_pull`), force per width in N/cm
      against strain in %, from 0 to the fitted stretch range, beside its small-strain law
      (:meth:`ShellMaterial.uniaxial_stiffness`, dashed). CSV columns: ``strain [%]``, then per
      direction ``<direction> force per width [N/cm]`` and ``<direction> small-strain law [N/cm]``.
    - ``<fabric>-bending.png``, ``.svg``, ``.csv``: moment per width (gf·cm/cm) against curvature
      (1/cm) of cylindrical bends along weft, warp and bias, the bending rigidities of the
      engineering constants (:meth:`ShellMaterial.engineering`) in gf·cm²/cm as slopes. CSV
      columns: ``curvature [1/cm]``, ``<direction> moment per width [gf*cm/cm]``.
    - ``<fabric>-bending-rigidity.csv``: ``direction``, ``bending rigidity [N*m]``, ``bending
      rigidity [gf*cm^2/cm]``.

    Returns:
        the paths written, in the order above.

    Raises:
        ValueError: the file cannot be read, keeps no samples (``<file>: no yarn-level samples``)
            or has a malformed entry (one line naming the file and the key).
        OSError: ``out_dir`` cannot be created (one line naming it).
    """
    file = MaterialFile.read(material)
    samples = file.samples()
    shell = file.shell
    rest = file.rest_state()
    fit = file.data.get("fit") if isinstance(file.data.get("fit"), Mapping) else {}
    quality = fit.get("families") if isinstance(fit.get("families"), Mapping) else {}
    folder = output_directory(out_dir)
    stem = file_stem(file.name)
    written: list[Path] = []
    for family in FAMILIES:
        members = [s for s in samples if s.family == family]
        if members:
            written += _family_figure(file.name, folder / f"{stem}-fit-{family}", family, members, shell,
                                      shell_energy_of(members, rest.energy, rest.residual_stress, rest.bending_energy),
                                      quality.get(family), rest.energy != 0.0 or any(rest.residual_stress.values()))
    stretch_range = _positive_or(fit.get("stretch_range"), DEFAULT_STRETCH_RANGE)
    written += _tension_figure(file.name, folder / f"{stem}-tension", shell, stretch_range)
    curvature_range = _positive_or(fit.get("curvature_range_per_m"), None)
    curvature_range = DEFAULT_CURVATURE_RANGE_PER_CM if curvature_range is None else curvature_range / CM_PER_M
    written += _bending_figure(file.name, folder / f"{stem}-bending", shell, curvature_range)
    return written


# Room left above and below the plotted energies, as a fraction of their span (matplotlib's own
# default margin).
ENERGY_MARGIN = 0.05


def energy_scale(energies: np.ndarray) -> tuple[float, float] | None:
    """The energy axis's limits (J/m²) for the fitted ``energies`` (the shell's curve and the
    samples it was fitted to; non-finite ones ignored): their range and :data:`ENERGY_MARGIN` of it
    either side (of their size for a single value), ``None`` if there are none."""
    energies = np.asarray(energies, dtype=float)
    energies = energies[np.isfinite(energies)]
    if not energies.size:
        return None
    low, high = float(energies.min()), float(energies.max())
    margin = ENERGY_MARGIN * ((high - low) if high > low else max(abs(high), 1.0))
    return low - margin, high + margin


def _family_figure(fabric: str, base: Path, family, samples: list[SampleResult], shell: ShellMaterial,
                   shell_part: np.ndarray, quality: Mapping | None, rest_state: bool) -> list[Path]:
    """One family's samples (``shell_part (n,)``: their Ū as the shell sees it, J/m²) against the
    shell's curve; ``base`` the path without suffix; ``rest_state``: the fit took a rest energy or
    residual stress out of the samples (the figure says so)."""
    membrane = family.group is Group.MEMBRANE
    scale = PERCENT if membrane else 1.0
    unit = "%" if membrane else "1/m"
    quantity = family.quantity.replace("λ − 1", "lambda - 1")  # the CSV's header stays ASCII
    parameter = np.array([s.parameter for s in samples])
    solved = np.array([s.energy_density for s in samples])
    converged = np.array([s.converged for s in samples], dtype=bool)
    curve_p, curve_w = shell_curve(shell, family, parameter)

    figure, ax = _figure()
    left_out = ~converged & np.isfinite(shell_part)
    ax.plot(scale * curve_p, curve_w, "-", color=SHELL_COLOR / _RGB, lw=1.5, label="fitted shell", zorder=2)
    ax.plot(scale * parameter[converged], shell_part[converged], "o", color=SAMPLE_COLOR / _RGB, ms=5,
            label="yarn level (fitted)", zorder=3)
    no_energy = int(np.sum(~converged & ~np.isfinite(shell_part)))
    # A sample left out is where its solve stopped, which can be anything (cotton jersey's jammed
    # weft compression: 2e6 J/m² beside samples of a few): it does not set the scale.
    limits = energy_scale(np.concatenate([curve_w, shell_part[converged]]))
    off_scale = np.zeros_like(left_out)
    if limits is not None:
        ax.set_ylim(*limits)
        off_scale = left_out & ((shell_part < limits[0]) | (shell_part > limits[1]))
    shown = left_out & ~off_scale
    if left_out.any() or no_energy:
        label = "yarn level, not converged (left out)"
        if off_scale.any():
            label += f"; {int(off_scale.sum())} off the scale"
        if no_energy:
            label += f"; {no_energy} without an energy"
        ax.plot(scale * parameter[shown], shell_part[shown], "x", color=EXCLUDED_COLOR / _RGB, ms=7, mew=1.5,
                label=label, zorder=4)
    ax.set_xlabel(f"{family.replace('_', ' ')}: {family.quantity} ({unit})")
    ax.set_ylabel("energy density (J/m²)")
    title = f"{fabric}: {family.replace('_', ' ')} samples and the fitted shell"
    if quality and isinstance(quality.get("r2"), (int, float)) and quality.get("samples", 0) > 1:
        title += f" (R² = {quality['r2']:.4f})"
    ax.set_title(title)
    if rest_state:
        ax.text(0.99, 0.01, "samples less the rest energy and residual-stress terms fitted beside the shell",
                transform=ax.transAxes, fontsize="x-small", color="0.4", ha="right", va="bottom")
    ax.axhline(0.0, color="0.8", lw=0.8, zorder=1)
    ax.legend(loc="best", fontsize="small")
    series = [
        Series("yarn level", scale * parameter[converged], shell_part[converged],
               {"energy density as solved [J/m^2]": solved[converged]}, converged[converged]),
        Series("yarn level, not converged", scale * parameter[~converged], shell_part[~converged],
               {"energy density as solved [J/m^2]": solved[~converged]}, converged[~converged]),
        Series("shell", scale * curve_p, curve_w),
    ]
    return _save(figure, base) + [_write_long_table(base.with_suffix(".csv"), f"{quantity} [{unit}]",
                                                    "energy density [J/m^2]", series)]


def _tension_figure(fabric: str, base: Path, shell: ShellMaterial, stretch_range: float) -> list[Path]:
    """The shell's uniaxial force–strain curve per direction, 0 to ``stretch_range``."""
    strain = np.linspace(0.0, stretch_range, CURVE_POINTS)
    figure, ax = _figure()
    columns = {"strain [%]": PERCENT * strain}
    for direction, degrees in PULL_DIRECTIONS.items():
        angle = math.radians(degrees)
        force = np.full(strain.shape, math.nan)
        for k, e in enumerate(strain):
            try:
                force[k] = shell.uniaxial_pull(angle, 1.0 + e).force_n_per_m / N_PER_M_IN_N_PER_CM
            except ValueError:
                # Beyond here no free width balances the pull (a StVK membrane of a large Poisson
                # ratio collapses its width): the curve ends, and the table says nan.
                break
        small = shell.uniaxial_stiffness(angle)[0] * strain / N_PER_M_IN_N_PER_CM
        color = DIRECTION_COLORS[direction]
        ends = "" if np.isfinite(force).all() else \
            f", ends at {PERCENT * strain[np.isfinite(force)].max():.3g} %: the width collapses"
        ax.plot(PERCENT * strain, force, "-", color=color, lw=1.8, label=f"{direction} ({degrees:g}°){ends}")
        ax.plot(PERCENT * strain, small, "--", color=color, lw=0.9, alpha=0.7)
        columns[f"{direction} force per width [N/cm]"] = force
        columns[f"{direction} small-strain law [N/cm]"] = small
    ax.plot([], [], "--", color="0.4", lw=0.9, label="small-strain law (dashed)")
    ax.set_xlabel("strain (%)")
    ax.set_ylabel("force per width (N/cm)")
    ax.set_title(f"{fabric}: uniaxial tension of the fitted shell (width free)")
    ax.set_xlim(0.0, PERCENT * stretch_range)
    ax.set_ylim(bottom=0.0)
    ax.legend(loc="upper left", fontsize="small")
    return _save(figure, base) + [_write_wide_table(base.with_suffix(".csv"), columns)]


def _bending_figure(fabric: str, base: Path, shell: ShellMaterial, curvature_range_per_cm: float) -> list[Path]:
    """Moment per width against curvature per direction (slopes: the bending rigidities), and the
    rigidities' own table."""
    engineering = shell.engineering()
    curvature = np.linspace(0.0, curvature_range_per_cm, CURVE_POINTS)
    figure, ax = _figure()
    columns = {"curvature [1/cm]": curvature}
    rigidities = []
    for direction in BENDING_DIRECTIONS:
        rigidity_nm = engineering[f"bending_{direction}_nm"]
        rigidity = rigidity_nm / GF_CM2_PER_CM
        moment = rigidity * curvature
        ax.plot(curvature, moment, "-", color=DIRECTION_COLORS[direction], lw=1.8,
                label=f"{direction}: B = {rigidity:.4g} gf·cm²/cm")
        columns[f"{direction} moment per width [gf*cm/cm]"] = moment
        rigidities.append((direction, rigidity_nm, rigidity))
    ax.set_xlabel("curvature (1/cm)")
    ax.set_ylabel("bending moment per width (gf·cm/cm)")
    ax.set_title(f"{fabric}: bending of the fitted shell")
    ax.set_xlim(0.0, curvature_range_per_cm)
    ax.set_ylim(bottom=0.0)
    ax.legend(loc="upper left", fontsize="small")
    table = base.with_name(f"{base.name}-rigidity.csv")
    with _open_table(table) as f:
        writer = csv.writer(f)
        writer.writerow(["direction", "bending rigidity [N*m]", "bending rigidity [gf*cm^2/cm]"])
        writer.writerows((d, repr(n), repr(g)) for d, n, g in rigidities)
    return _save(figure, base) + [_write_wide_table(base.with_suffix(".csv"), columns), table]


# -- the validation -----------------------------------------------------------------------------


def validation_figures(summary: str | os.PathLike | Mapping, out_dir: str | os.PathLike,
                       reference: str | os.PathLike | Reference | None = None, *,
                       material: str | os.PathLike | Mapping | MaterialFile | None = None) -> list[Path]:
    """The stretch-test curves of a validation run, per direction, written to ``out_dir``.

    Args:
        summary: what :func:`yarnfit.validate.suite.run_suite` returns first (the dict
            ``summary.json`` holds), or the path of ``summary.json``. Read: ``material.name``, the
            ``stretch`` scene's strips (:class:`yarnfit.validate.stretch.StripResult` summaries:
            ``strain``, ``force_per_width_n_per_m``, ``settled``, ``stable``,
            ``uniaxial_law_n_per_m``), the ``yarn`` scene's curves per direction
            (:func:`yarnfit.validate.swatch.stretch_swatch`: ``strain``, ``force_n_per_m``, ``points``
            with ``converged``) and ``shell_vs_yarn.shell_strips`` (the shell's quasi-static strips
            of the swatch's size and jaws, ``converged`` per level), whichever ran.
        out_dir: the directory to write to (created if missing).
        reference: a measured curve (:class:`yarnfit.validate.reference.Reference`, or the path of
            its CSV, read by :func:`~yarnfit.validate.reference.read_reference`), or ``None``.
        material: the fitted material file (path, JSON or
            :class:`~yarnfit.material_file.MaterialFile`), or ``None``. With it the shell's law is its
            uniaxial tension at large strain (:meth:`ShellMaterial.uniaxial_pull`); without it, the
            small-strain law ``uniaxial_law_n_per_m × strain`` of the summary.

    Written, ``<fabric>`` = :func:`file_stem` of ``material.name``, for each direction (weft, warp,
    bias) with a curve: ``<fabric>-stretch-<direction>.png``, ``.svg``, ``.csv``. Force per width
    (N/cm) against engineering strain (%): each shell strip in MuJoCo (line with dots; crosses at
    levels that did not come to rest or met an unstable step), the yarn-level swatch (squares;
    crosses where a solve did not converge) and its middle half's pull against its middle's strain
    (hollow squares, where the points carry them: where the swatch is uniform), the reference
    (black diamonds) and the shell's law (thin grey line; the strips' clamped ends make them
    stiffer than it for a fabric with a large Poisson ratio). CSV columns: ``series``,
    ``strain [%]``, ``force per width [N/cm]``, ``compression ratio [1]`` (empty where not
    measured) and ``converged`` (empty for the law).

    Returns:
        the paths written.

    Raises:
        ValueError: the summary cannot be read, is not a ``yarnfit validate`` summary, or has no
            stretch curves (neither the ``stretch`` nor the ``yarn`` scene ran); a bad reference file.
        OSError: ``out_dir`` cannot be created.
    """
    where, data = ("summary", summary) if isinstance(summary, Mapping) else read_json(summary, "validation summary")
    if not isinstance(data, Mapping) or not isinstance(data.get("scenes"), Mapping):
        raise ValueError(f"{where}: not a `yarnfit validate` summary (no 'scenes')")
    name = _name_of(data)
    if reference is not None and not isinstance(reference, Reference):
        reference = read_reference(reference)
    shell = MaterialFile.read(material).shell if material is not None else None
    scenes = data["scenes"]
    strips = {**_mapping(_mapping(scenes.get("stretch")).get("strips")),
              **_mapping(_mapping(data.get("shell_vs_yarn")).get("shell_strips"))}
    yarn = _mapping(_mapping(scenes.get("yarn")).get("directions"))
    try:
        plotted = {direction: _stretch_series(direction, strips, yarn, reference) for direction in DIRECTIONS}
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"{where}: a stretch curve is malformed ({type(exc).__name__}: {exc})") from None
    plotted = {direction: series for direction, series in plotted.items() if series}
    if not plotted:
        raise ValueError(f"{where}: no stretch curves (run `yarnfit validate` with the scenes stretch or yarn)")
    folder = output_directory(out_dir)
    stem = file_stem(name)
    written: list[Path] = []
    for direction, series in plotted.items():
        law = _law_series(direction, strips, series, shell)
        written += _stretch_figure(name, folder / f"{stem}-stretch-{direction}", direction, series, law)
    return written


def _stretch_series(direction: str, strips: Mapping, yarn: Mapping, reference: Reference | None) -> list[Series]:
    """The measured curves of one direction, in N/cm against %: shell strips, yarn swatch, reference."""
    out = []
    shown = [(name, strip) for name, strip in strips.items() if name.endswith(f"_{direction}")]
    for (strip_name, strip), color in zip(shown, STRIP_COLORS):
        strain = np.asarray(strip["strain"], dtype=float)
        ok = (np.asarray(strip.get("settled", [True] * len(strain)), bool)
              & np.asarray(strip.get("stable", [True] * len(strain)), bool)
              & np.asarray(strip.get("converged", [True] * len(strain)), bool))
        label = (f"shell in MuJoCo, {CM_PER_M * strip['length_m']:.3g} x {CM_PER_M * strip['width_m']:.3g} cm strip"
                 if "length_m" in strip else f"shell in MuJoCo, strip {strip_name}")
        if strip.get("quasi_static"):  # suite.shell_strips_like_swatch: the swatch's own test
            label = "shell, quasi-static, the swatch's size and jaws"
        elif strip_name.startswith("swatch_"):  # written before session 49: MuJoCo strips
            label += " (the swatch's proportions)"
        out.append(Series(label, PERCENT * strain,
                          np.asarray(strip["force_per_width_n_per_m"], float) / N_PER_M_IN_N_PER_CM,
                          {"compression ratio [1]": np.asarray(strip.get("compression_ratio", [math.nan] * len(strain)),
                                                               float)}, ok, {"color": color, **STRIP_STYLE}))
    curve = yarn.get(direction)
    if isinstance(curve, Mapping):
        strain = np.asarray(curve["strain"], dtype=float)
        points = curve.get("points")
        ok = (np.array([bool(p.get("converged", True)) for p in points]) if isinstance(points, list)
              and len(points) == len(strain) else np.full(len(strain), bool(curve.get("converged", True))))
        size = (f"{CM_PER_M * curve['gauge_m']:.3g} x {CM_PER_M * curve['width_m']:.3g} cm swatch"
                if "gauge_m" in curve and "width_m" in curve else "swatch")
        out.append(Series(f"yarn level, {size}", PERCENT * strain,
                          np.asarray(curve["force_n_per_m"], float) / N_PER_M_IN_N_PER_CM,
                          {"compression ratio [1]": np.asarray(curve.get("compression_ratio",
                                                                         [math.nan] * len(strain)), float)}, ok,
                          YARN_STYLE))
        middle = _middle_series(curve, ok)
        if middle is not None:
            out.append(middle)
    if reference is not None and direction in reference.curves:
        measured = reference.curves[direction]
        out.append(Series(f"measured: {reference.name}", PERCENT * measured.strain,
                          measured.force_per_width / N_PER_M_IN_N_PER_CM,
                          {"compression ratio [1]": measured.compression_ratio}, np.ones(len(measured.strain), bool),
                          MEASURED_STYLE))
    return out


def _middle_series(curve: Mapping, ok: np.ndarray) -> Series | None:
    """The swatch where it is uniform: its middle half's pull against the strain its middle
    reached (``middle_force_n_per_m`` and ``mid_strain`` of each point; its width ratio
    ``middle_compression_ratio``), the pair a free pull of the shell's law should match; ``None``
    for curves without them (older runs) or where a mark held no node."""
    points = curve.get("points")
    if not isinstance(points, list) or not points:
        return None
    force = [p.get("middle_force_n_per_m") for p in points]
    strain = [p.get("mid_strain") for p in points]
    if any(v is None for v in force + strain):
        return None
    return Series("yarn level, middle half at its own strain", PERCENT * np.asarray(strain, float),
                  np.asarray(force, float) / N_PER_M_IN_N_PER_CM,
                  {"compression ratio [1]": np.asarray([_or_nan(p.get("middle_compression_ratio")) for p in points],
                                                       float)},
                  ok if len(ok) == len(points) else np.ones(len(points), bool), YARN_MIDDLE_STYLE)


def _or_nan(value) -> float:
    return math.nan if value is None else float(value)


def _law_series(direction: str, strips: Mapping, series: list[Series], shell: ShellMaterial | None) -> Series | None:
    """The shell's law over the direction's plotted strains: its uniaxial tension if ``shell`` is
    given, else the summary's small-strain law; ``None`` if neither is known."""
    top = max(float(np.max(s.x, initial=0.0)) for s in series) / PERCENT
    if top <= 0.0:
        return None
    strain = np.linspace(0.0, top, CURVE_POINTS)
    nan = np.full(len(strain), math.nan)
    if shell is not None:
        angle = math.radians(DIRECTIONS[direction])
        force = np.array([shell.uniaxial_pull(angle, 1.0 + e).force_n_per_m for e in strain])
        return Series("shell law, width free", PERCENT * strain, force / N_PER_M_IN_N_PER_CM,
                      {"compression ratio [1]": nan}, style=LAW_STYLE)
    laws = [s["uniaxial_law_n_per_m"] for n, s in strips.items() if n.endswith(f"_{direction}")
            and isinstance(s.get("uniaxial_law_n_per_m"), (int, float))]
    if not laws:
        return None
    return Series("shell law at small strain, width free", PERCENT * strain, laws[0] * strain / N_PER_M_IN_N_PER_CM,
                  {"compression ratio [1]": nan}, style=LAW_STYLE)


def _stretch_figure(fabric: str, base: Path, direction: str, series: list[Series], law: Series | None) -> list[Path]:
    """One direction's curves (each drawn in its own ``style``) and the shell's law."""
    figure, ax = _figure()
    any_failed = False
    for s in series:
        # Markers only where the point converged or came to rest; a cross at the others.
        ax.plot(s.x, s.y, label=s.label, markevery=None if s.ok.all() else list(np.flatnonzero(s.ok)), **s.style)
        failed = ~s.ok
        if failed.any():
            any_failed = True
            ax.plot(s.x[failed], s.y[failed], "x", color=s.style.get("color"), ms=8, mew=1.8)
    if law is not None:
        ax.plot(law.x, law.y, label=law.label, **law.style)
    if any_failed:
        ax.plot([], [], "x", color="0.3", ms=8, mew=1.8, label="not at rest / not converged")
    ax.set_xlabel("strain (%)")
    ax.set_ylabel("force per width (N/cm)")
    ax.set_title(f"{fabric}: stretch test, {direction} ({DIRECTIONS[direction]:g}°)")
    ax.set_xlim(left=0.0)
    ax.set_ylim(bottom=min(0.0, *(float(np.nanmin(s.y, initial=0.0)) for s in series)))
    ax.legend(loc="upper left", fontsize="small")
    tables = series + ([law] if law is not None else [])
    return _save(figure, base) + [_write_long_table(base.with_suffix(".csv"), "strain [%]", "force per width [N/cm]",
                                                    tables)]


# -- shared helpers -------------------------------------------------------------------------------


def file_stem(name: str) -> str:
    """``name`` as the start of a file name: every run of characters other than letters, digits,
    ``.``, ``_`` and ``-`` becomes one ``_`` (``"cotton twill/2"`` → ``"cotton_twill_2"``);
    ``"fabric"`` if nothing is left."""
    stem = re.sub(r"[^A-Za-z0-9._-]+", "_", str(name)).strip("._")
    return stem or "fabric"


def output_directory(out_dir: str | os.PathLike) -> Path:
    """``out_dir`` as a Path, created with its parents if missing. OSError in one line naming it
    if it cannot be (a file in the way, no permission)."""
    folder = Path(out_dir)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OSError(f"{folder}: cannot create the figure directory ({exc.strerror or exc})") from None
    return folder


def _figure():
    """A figure with one axes, laid out so that labels never overlap (Figure, not pyplot: no
    global state, no display)."""
    figure = Figure(figsize=FIGURE_INCHES, layout="constrained")
    ax = figure.subplots()
    ax.grid(True, color="0.9", lw=0.6)
    return figure, ax


def _save(figure: Figure, base: Path) -> list[Path]:
    """``base.png`` and ``base.svg``. The SVG carries no date, so an unchanged figure is an
    unchanged file."""
    png, svg = base.with_name(base.name + ".png"), base.with_name(base.name + ".svg")
    figure.savefig(png, dpi=PNG_DPI)
    figure.savefig(svg, metadata={"Date": None})
    return [png, svg]


def _open_table(path: Path):
    return open(path, "w", newline="", encoding="utf-8")


def _number(value: float) -> str:
    """A cell: the float as repr (round-trips), empty for NaN (a value not measured)."""
    return "" if not math.isfinite(value) else repr(float(value))


def _write_wide_table(path: Path, columns: Mapping[str, np.ndarray]) -> Path:
    """One column per header, rows aligned."""
    with _open_table(path) as f:
        writer = csv.writer(f)
        writer.writerow(list(columns))
        writer.writerows([_number(v) for v in row] for row in zip(*columns.values()))
    return path


def _write_long_table(path: Path, x_header: str, y_header: str, series: Sequence[Series]) -> Path:
    """One row per plotted point: ``series``, x, y, the series' extra columns (empty where a series
    has none), ``converged`` (``true``/``false``; empty for a curve)."""
    extra = list(dict.fromkeys(key for s in series for key in s.extra))
    with _open_table(path) as f:
        writer = csv.writer(f)
        writer.writerow(["series", x_header, y_header, *extra, "converged"])
        for s in series:
            for k in range(len(s.x)):
                cells = [_number(s.extra[key][k]) if key in s.extra else "" for key in extra]
                ok = "" if s.ok is None else str(bool(s.ok[k])).lower()
                writer.writerow([s.label, _number(s.x[k]), _number(s.y[k]), *cells, ok])
    return path


def _positive_or(value: object, default):
    """``value`` if it is a finite positive number, else ``default``."""
    if isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and value > 0:
        return float(value)
    return default


def _mapping(value: object) -> Mapping:
    return value if isinstance(value, Mapping) else {}


def _name_of(summary: Mapping) -> str:
    material = summary.get("material")
    name = material.get("name") if isinstance(material, Mapping) else None
    return name if isinstance(name, str) and name.strip() else "material"
