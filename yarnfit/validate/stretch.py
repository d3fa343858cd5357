"""FAB-style stretch tests of a fitted material in MuJoCo (issue 6, item 1).

Strips 8 × 5 cm and 2 × 5 cm (length between the clamps × width), cut along weft, warp and bias
(45°), are clamped on their short sides in the exported ``stretch`` scene
(:func:`yarnfit.mujoco.scenes.build_scene`): the left clamp is the world, the right one a body on
slide joint ``pull`` driven by position actuator ``pull``. The pull goes quasi-statically through
:data:`STRAIN_LEVELS` up to the largest strain asked for: the actuator target is ramped to each
level over :data:`RAMP_SECONDS`, then held until every vertex and the clamp move slower than
:data:`REST_STRAIN_RATE` times the strip's length, and only then are the clamp force (sensor
``pull_force``, N), its displacement (sensor ``pull_extension``, m: the servo lags its target by
about 1 %, so the strain is measured, not commanded) and the width at mid-length read. Per strip: force per unit width (N/m) and compression ratio (width at
mid-length over the initial width) against engineering strain.

The small-strain uniaxial law of the shell (``ShellMaterial.uniaxial_stiffness``: ``weft_stretch_n_per_m``
and its rotated form, design notes §3) is reported beside the first level: clamped ends hold the strip's width, so a strip
whose Poisson ratio is large reads stiffer than the uniaxial law; a material with zero Poisson
ratio reads the law itself (tested).

Recording (``logs/<material>/stretch.rrd``, one stream as in :mod:`yarnfit.record`): timeline
``strain_step`` (sequence: the strain level's index, level 0 the unstrained strip); entity paths

- ``stretch/<strip>/cloth``: ``Mesh3D``, the strip at each level (m), ``<strip>`` =
  ``<length>x<width>_<direction>`` such as ``8x5_weft``;
- ``stretch/plots/force/<strip>``: ``Scalars``, clamp force per width (N/m);
- ``stretch/plots/compression/<strip>``: ``Scalars``, compression ratio (1);
- ``stretch/plots/reference_force/<direction>``: ``Scalars``, a reference curve's force per width
  interpolated at the levels, when one is given;
- ``stretch/summary``: ``TextDocument`` (markdown).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from ..record import _markdown_table, _Recording
from ..mujoco.scenes import SceneMaterial, build_scene, compile_quietly

# FAB strips (m): length between the clamps × width.
STRIPS = {"8x5": (0.08, 0.05), "2x5": (0.02, 0.05)}
DIRECTIONS = {"weft": 0.0, "warp": math.pi / 2, "bias": math.pi / 4}
# Engineering strain levels of the pull (the 2 %, 5 % and 10 % the yarn comparison reads, and
# small ones for the law).
STRAIN_LEVELS = (0.002, 0.005, 0.01, 0.02, 0.05, 0.1)
# Vertices along the strip (the width gets the same spacing): full and quick (CI).
RESOLUTION = {False: 25, True: 9}
# Seconds over which the clamp moves from one level to the next: slow against the strip's and the
# servo's time constants (ms), so the pull is quasi-static.
RAMP_SECONDS = 0.05
# A level is read once every vertex and the clamp move slower than this strain rate times the
# strip's length (1/s): at 1e-4 /s the strain drifts by 1e-7 per millisecond step, 0.05 % of the
# smallest level.
REST_STRAIN_RATE = 1e-4
# Longest hold per level (s); a strip that has not come to rest by then is reported as not settled.
MAX_HOLD_SECONDS = 1.0


@dataclass(frozen=True)
class StripResult:
    """One strip's pull. Arrays ``(levels,)``."""

    name: str
    length_m: float
    width_m: float
    angle_rad: float
    strain: np.ndarray  # measured: clamp displacement over length
    force_per_width_n_per_m: np.ndarray
    compression_ratio: np.ndarray
    settled: np.ndarray  # bool: came to rest within MAX_HOLD_SECONDS
    wall_seconds: float


def pull_strip(material: SceneMaterial, strip: str, direction: str, *, quick: bool = False,
               max_strain: float = STRAIN_LEVELS[-1], on_level: Callable | None = None) -> StripResult:
    """Pull one strip through the strain levels up to ``max_strain``. ``on_level(index, strain,
    positions (n, 3), triangles (m, 3), force, ratio)`` is called at each level, level 0 the rest
    state."""
    import mujoco

    length, width = STRIPS[strip]
    angle = DIRECTIONS[direction]
    levels = [e for e in STRAIN_LEVELS if e <= max_strain + 1e-12]
    if not levels:
        raise ValueError(f"max_strain must be at least {STRAIN_LEVELS[0]}, got {max_strain!r}")
    built = build_scene(material, "stretch", resolution=RESOLUTION[quick], size=length, width=width,
                        angle=angle, max_strain=levels[-1])
    model = compile_quietly(built.spec)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    rest = data.flexvert_xpos.copy()
    triangles = model.flex_elem.reshape(-1, 3).copy()
    middle = np.isclose(rest[:, 0], np.median(np.unique(np.round(rest[:, 0], 12))))
    force_sensor = model.sensor("pull_force").adr[0]
    extension_sensor = model.sensor("pull_extension").adr[0]
    rest_speed = REST_STRAIN_RATE * length
    dt = model.opt.timestep
    start = time.perf_counter()

    def width_at_middle() -> float:
        y = data.flexvert_xpos[middle, 1]
        return float(y.max() - y.min())

    if on_level:
        on_level(0, 0.0, rest, triangles, 0.0, 1.0)
    strains, forces, ratios, settled = [], [], [], []
    target = 0.0
    for index, strain in enumerate(levels, start=1):
        ramp_steps = max(1, round(RAMP_SECONDS / dt))
        goal = strain * length
        for k in range(1, ramp_steps + 1):
            data.ctrl[0] = target + (goal - target) * k / ramp_steps
            mujoco.mj_step(model, data)
        target = goal
        rested = False
        for _ in range(round(MAX_HOLD_SECONDS / dt)):
            mujoco.mj_step(model, data)
            if np.abs(data.qvel).max() < rest_speed:
                rested = True
                break
        mujoco.mj_forward(model, data)
        force = float(data.sensordata[force_sensor]) / width
        ratio = width_at_middle() / width
        strain = float(data.sensordata[extension_sensor]) / length
        strains.append(strain)
        forces.append(force)
        ratios.append(ratio)
        settled.append(rested)
        if on_level:
            on_level(index, strain, data.flexvert_xpos.copy(), triangles, force, ratio)
    return StripResult(f"{strip}_{direction}", length, width, angle, np.array(strains), np.array(forces),
                       np.array(ratios), np.array(settled), time.perf_counter() - start)


def run_stretch(material: SceneMaterial | str | Path, *, quick: bool = False, recording_path=None,
                progress: Callable[[str], None] | None = None, reference=None,
                max_strain: float = STRAIN_LEVELS[-1]) -> dict:
    """Every strip in every direction; returns the summary figures (keys carry units)."""
    if not isinstance(material, SceneMaterial):
        material = SceneMaterial.from_file(material)
    recording = _StretchRecording(material.name, recording_path) if recording_path else None
    results = []
    strips = ["8x5"] if quick else list(STRIPS)
    for strip in strips:
        for direction in DIRECTIONS:
            name = f"{strip}_{direction}"
            if progress:
                progress(f"stretch {name}")
            callback = recording.level_logger(name) if recording else None
            results.append(pull_strip(material, strip, direction, quick=quick, max_strain=max_strain,
                                      on_level=callback))
    summary = {"strips": {}}
    for result in results:
        stiffness, poisson = material.shell.uniaxial_stiffness(result.angle_rad)
        first = result.strain[0]
        summary["strips"][result.name] = {
            "length_m": result.length_m,
            "width_m": result.width_m,
            "angle_rad": result.angle_rad,
            "strain": result.strain.tolist(),
            "force_per_width_n_per_m": result.force_per_width_n_per_m.tolist(),
            "compression_ratio": result.compression_ratio.tolist(),
            "settled": result.settled.tolist(),
            "uniaxial_law_n_per_m": stiffness,
            "uniaxial_law_poisson": poisson,
            "small_strain_stiffness_over_law": float(result.force_per_width_n_per_m[0] / first / stiffness),
            "wall_seconds": result.wall_seconds,
        }
    if reference is not None:
        from .reference import compare

        summary["reference"] = compare(reference, summary["strips"])
        if recording:
            recording.log_reference(reference, summary["strips"])
    if recording:
        recording.finish(summary)
    return summary


class _StretchRecording(_Recording):
    """``logs/<material>/stretch.rrd`` (see the module docstring)."""

    def __init__(self, name: str, path) -> None:
        layout = rrb.Blueprint(rrb.Horizontal(
            rrb.Spatial3DView(origin="stretch", contents=["+ stretch/**", "- stretch/plots/**"], name="strips"),
            rrb.Vertical(rrb.TimeSeriesView(origin="stretch/plots/force", name="force per width (N/m)"),
                         rrb.TimeSeriesView(origin="stretch/plots/compression", name="compression ratio"),
                         rrb.TextDocumentView(origin="stretch/summary", name="summary")),
        ))
        super().__init__(name, path, layout, "stretch")

    def level_logger(self, name: str) -> Callable:
        stream = self._rec

        def log(index, strain, positions, triangles, force, ratio):
            stream.set_time("strain_step", sequence=index)
            stream.log(f"stretch/{name}/cloth", rr.Mesh3D(vertex_positions=positions, triangle_indices=triangles))
            stream.log(f"stretch/plots/force/{name}", rr.Scalars(force))
            stream.log(f"stretch/plots/compression/{name}", rr.Scalars(ratio))

        return log

    def log_reference(self, reference, strips: dict) -> None:
        stream = self._rec
        for direction, curve in reference.curves.items():
            levels = next(iter(s["strain"] for n, s in strips.items() if n.endswith(direction)), [])
            for index, strain in enumerate(levels, start=1):
                if curve.strain[0] <= strain <= curve.strain[-1]:
                    stream.set_time("strain_step", sequence=index)
                    stream.log(f"stretch/plots/reference_force/{direction}",
                               rr.Scalars(float(np.interp(strain, curve.strain, curve.force_per_width))))

    def finish(self, summary: dict) -> None:
        rows = [(name, f"{e:g}", f"{f:.4g}", f"{c:.4f}", f"{s['uniaxial_law_n_per_m'] * e:.4g}")
                for name, s in summary["strips"].items()
                for e, f, c in zip(s["strain"], s["force_per_width_n_per_m"], s["compression_ratio"])]
        self._log_markdown("stretch/summary", _markdown_table(rows, ("strip", "strain", "N/m", "compression", "law N/m")),
                           static=True)
        self.close()
