"""``yarnfit validate``: run the validation scenes on one material file, record each to
``<logs>/<material>/<scene>.rrd`` (the yarn scene to ``yarn_<direction>.rrd``) and write every
figure to ``<logs>/<material>/summary.json``.

``summary.json``: ``yarnfit_version``, ``material`` (file, name), ``quick``, ``scenes`` (scene →
its runner's summary, keys carrying their units), ``wall_seconds`` (scene → s, and
``shell_strips_like_swatch`` when it ran; each task's own, not the suite's) and, when both
``stretch`` and ``yarn`` ran, ``shell_vs_yarn``: the yarn swatch against the shell in its own
test, a quasi-static strip of the swatch's gauge and width between the same jaws
(``same_proportions``, :func:`shell_strips_like_swatch`), and against the 8 × 5 FAB strips in
MuJoCo (``fab_8x5``), both by :func:`compare_shell_yarn`; with ``stretch``,
``bias_softness`` (the paper's check (a), :func:`yarnfit.validate.paper.bias_softness`).

The scenes are independent (each reads the material file and writes its own recording), so they
run as tasks of :mod:`yarnfit.tasks` on a :class:`~yarnfit.tasks.Backend`: one at a time in this
process by default, or side by side on worker processes (``yarnfit validate`` uses every core).
The yarn scene runs as one task per direction (recorded to ``yarn_<direction>.rrd``; its summary
merged by :func:`~yarnfit.validate.swatch.merge_yarn_summaries`), each followed by its own shell
strip (seconds): its strips are the suite's longest computations, the twill's warp strip alone
477 s of its 638 (session 33).
On 2 cores the cotton twill's full suite took 613.5 s one scene after another and 407.7 s two at a
time (session 28, ``yarnfit validate --workers 1`` against the default); every figure of the two
summaries was the same, each scene being a deterministic computation of its own. Two scenes at once
run ~1.5× slower each (stretch 204 → 291 s, yarn 183 → 282 s): they share the memory bus.
"""

from __future__ import annotations

import json
import math
import multiprocessing
import threading
import time
from contextlib import contextmanager
from multiprocessing.managers import SyncManager
from pathlib import Path
from typing import Callable

from .. import __version__
from ..material_file import MaterialFile
from ..tasks import Backend, LocalPool, Result, SkippedTask, Task, ignore_sigint, run_tasks
from . import DRAPES, SCENES, jsonable
from .verdicts import verdicts


# How far past the shell's last measured strain a yarn point may lie and still be compared
# (relative): the servo leaves the measured strain below the nominal level, ~1 % for wovens, up to
# 5 % for the clamped strips of knits (a jersey's bias strip stops at 9.52 % of 10 %).
SHELL_RANGE_SLACK = 0.06
# The shell strips compared with the yarn swatch (shell_strips_like_swatch): the middle of the three
# meshes shell_strip_limit extrapolates from (rows across; yarnfit.validate.shell_strip).
LIKE_SWATCH_ROWS = {False: 24, True: 6}


def _runner(scene: str) -> Callable:
    if scene == "stretch":
        from .stretch import run_stretch
        return run_stretch
    if scene in DRAPES:
        from .drape import run_drape
        return lambda material, **options: run_drape(material, scene, **options)
    if scene == "body":
        from .body import run_body
        return run_body
    raise ValueError(f"unknown scene {scene!r}; scenes: {', '.join(SCENES)}")


# Expected wall time of each scene (s, full size, cotton twill, two at a time on 2 cores, session
# 57), so that the longest start first when scenes run side by side; quick runs keep the same order.
# The yarn scene's directions likewise (the warp strip first). With session 27's figures (stretch
# 187, sphere 43 s: before the drapes ran to rest and the creep test) the sphere started last and
# ran alone for its final 2 min: the twill's suite 479 s, and 440 s in this order (`yarnfit validate`).
SCENE_COST = {"stretch": 264.0, "sphere": 212.0, "wall": 100.0, "body": 44.0, "cusick": 36.0}
YARN_COST = {"warp": 123.0, "bias": 32.0, "weft": 16.0}
# The quasi-static shell strips of the swatch (all directions): seconds each.
LIKE_SWATCH_COST = 6.0


def run_scene(file: MaterialFile, scene: str, quick: bool, recording: Path, reference=None,
              progress: Callable[[str], None] | None = None) -> tuple[dict, float]:
    """One MuJoCo scene of the suite on the material file (read once by :func:`run_suite`; the yarn
    scene runs per direction, :func:`yarn_direction_task`), recorded to ``recording``: its summary
    and wall time (s). A task's function (module level, picklable arguments; ``progress`` a picklable
    :class:`ForwardedProgress` on worker processes)."""
    if progress:
        progress(f"{scene}: running")
    start = time.perf_counter()
    options = {"quick": quick, "recording_path": recording, "progress": progress}
    if scene == "stretch" and reference is not None:
        options["reference"] = reference
    from ..mujoco.scenes import ClothMaterial

    summary = _runner(scene)(ClothMaterial.from_file(file), **options).summary()
    return summary, time.perf_counter() - start


def yarn_direction_task(file: MaterialFile, direction: str, quick: bool, recording: Path,
                        progress: Callable[[str], None] | None = None) -> tuple[dict, float]:
    """The yarn scene's strip along one ``direction``, recorded to ``recording``: its summary and
    wall time (s), as :func:`run_scene` gives a scene's."""
    from .swatch import run_yarn

    if progress:
        progress(f"yarn: {direction} running")
    start = time.perf_counter()
    result = run_yarn(file, quick=quick, directions=(direction,), recording_path=recording, progress=progress)
    return result.summary(), time.perf_counter() - start


def like_swatch_task(material, quick: bool, yarn: tuple[dict, float]) -> tuple[dict, float]:
    """:func:`shell_strips_like_swatch` of one yarn direction task's outcome (``material`` a
    :class:`~yarnfit.mujoco.scenes.ClothMaterial`), timed like a scene: each direction's shell strip
    starts as soon as its yarn strip is pulled, so the longest yarn strip is followed by its own
    shell strip only."""
    start = time.perf_counter()
    like = shell_strips_like_swatch(material, yarn[0], quick=quick)
    return like, time.perf_counter() - start


class ForwardedProgress:
    """A scene's progress callback in a worker process: each line goes, prefixed with the scene,
    onto a queue the parent prints from (a ``multiprocessing.Manager`` queue: picklable, so it
    reaches forked and spawned workers alike)."""

    def __init__(self, queue, scene: str):
        self.queue, self.scene = queue, scene

    def __call__(self, message: str) -> None:
        self.queue.put(message if message.startswith(self.scene) else f"{self.scene}: {message}")


@contextmanager
def _forwarded_progress(progress: Callable[[str], None] | None, backend: Backend):
    """``None`` where progress cannot or need not be forwarded (no callback, scenes in this
    process, or a cluster whose workers cannot reach this machine's queue); otherwise a queue of
    the workers' lines, printed through ``progress`` by a thread here until the block ends."""
    if progress is None or not isinstance(backend, LocalPool) or backend.workers == 1:
        yield None
        return
    # Its server process ignores SIGINT like the workers: Ctrl-C reaches the whole process group,
    # and a manager stopped by it would fail the workers' next line instead of the run stopping.
    manager = SyncManager(ctx=multiprocessing.get_context())
    manager.start(ignore_sigint)
    try:
        queue = manager.Queue()

        def drain():
            while (line := queue.get()) is not None:
                progress(line)

        printer = threading.Thread(target=drain, name="yarnfit-suite-progress", daemon=True)
        printer.start()
        try:
            yield queue
        finally:
            queue.put(None)
            printer.join(timeout=5.0)
    finally:
        manager.shutdown()


def run_suite(material_path: str | Path, scenes=SCENES, *, quick: bool = False, logs: str | Path = "logs",
              reference=None, progress: Callable[[str], None] | None = None,
              backend: Backend | None = None) -> tuple[dict, Path]:
    """Run ``scenes`` on the material file; returns the summary and the path of ``summary.json``.

    ``backend`` runs the scenes (default: one after another in this process). Each scene reports its
    own progress, prefixed with its name when it runs on a local worker process (a cluster's
    workers report only each scene's end). The first scene that fails raises its exception once the
    others have finished."""
    unknown = [scene for scene in scenes if scene not in SCENES]
    if unknown:
        raise ValueError(f"unknown scene {unknown[0]!r}; scenes: {', '.join(SCENES)}")
    file = MaterialFile.read(material_path)
    file.check_version()
    from ..mujoco.scenes import ClothMaterial

    material = ClothMaterial.from_file(file)  # a file the scenes cannot read fails here, before any scene
    folder = Path(logs) / material.name
    folder.mkdir(parents=True, exist_ok=True)
    summary = {"yarnfit_version": __version__, "material": {"file": str(material_path), "name": material.name},
               "quick": quick, "scenes": {}, "wall_seconds": {}}
    backend = LocalPool(1) if backend is None else backend
    in_process = isinstance(backend, LocalPool) and backend.workers == 1

    from .swatch import merge_yarn_summaries, yarn_directions

    finished = set()
    yarn_keys = yarn_directions(quick) if "yarn" in scenes else ()
    like_swatch = "stretch" in scenes and "yarn" in scenes  # shell strips of the yarn swatch's proportions
    recordings = {}  # task key -> the recording it writes (a stopped worker's is part-written)

    def done(task, outcome, count, total):
        finished.add(task.key)
        if not progress:
            return
        if isinstance(outcome, BaseException):
            progress(f"{task.label}: failed ({type(outcome).__name__})")
        else:
            progress(f"{task.label}: done in {outcome[1]:.1f} s ({count}/{total})")

    with _forwarded_progress(progress, backend) as queue:
        def scene_progress(scene: str):
            if in_process:
                return progress
            return None if queue is None else ForwardedProgress(queue, scene)

        tasks = []
        for scene in scenes:
            if scene == "yarn":
                for direction in yarn_keys:
                    key = f"yarn_{direction}"
                    recordings[key] = folder / f"{key}.rrd"
                    tasks.append(Task(key, yarn_direction_task,
                                      (file, direction, quick, recordings[key], scene_progress("yarn")),
                                      cost=YARN_COST.get(direction, 0.0), cached=False, label=f"yarn {direction}"))
            else:
                recordings[scene] = folder / f"{scene}.rrd"
                tasks.append(Task(scene, run_scene,
                                  (file, scene, quick, recordings[scene], reference, scene_progress(scene)),
                                  cost=SCENE_COST.get(scene, 0.0), cached=False, label=scene))
        if like_swatch:
            tasks += [Task(f"like_swatch_{direction}", like_swatch_task, (material, quick, Result(f"yarn_{direction}")),
                           cost=LIKE_SWATCH_COST / len(yarn_keys), cached=False,
                           label=f"shell strip of the yarn swatch's proportions, {direction}")
                      for direction in yarn_keys]
        if progress and not in_process:
            workers = getattr(backend, "workers", None)
            progress(f"{len(tasks)} tasks on {f'{workers} worker processes' if workers else 'the cluster'}: "
                     + ", ".join(task.label for task in tasks))
        try:
            outcomes = run_tasks(tasks, backend, on_done=done)
        except KeyboardInterrupt:
            # Workers stopped mid-scene leave their recordings part-written (an in-process scene's
            # is discarded by the command line, yarnfit.record.Recording.discard_open).
            if not in_process:
                from ..record import Recording

                for key, recording in recordings.items():
                    if key not in finished:
                        Recording.partial_path(recording).unlink(missing_ok=True)
            raise
    failed = [outcomes[task.key] for task in tasks if isinstance(outcomes[task.key], BaseException)]
    first = next((error for error in failed if not isinstance(error, SkippedTask)), None)
    if first is not None:
        raise first
    for scene in scenes:
        if scene == "yarn":
            parts = [outcomes[f"yarn_{direction}"] for direction in yarn_keys]
            summary["scenes"]["yarn"] = merge_yarn_summaries([part[0] for part in parts])
            summary["wall_seconds"]["yarn"] = float(sum(part[1] for part in parts))
        else:
            summary["scenes"][scene], summary["wall_seconds"][scene] = outcomes[scene]
    if "stretch" in summary["scenes"]:
        from .paper import bias_softness

        summary["bias_softness"] = bias_softness(summary["scenes"]["stretch"])
    if like_swatch:
        parts = [outcomes[f"like_swatch_{direction}"] for direction in yarn_keys]
        like = {"strips": {name: strip for part in parts for name, strip in part[0]["strips"].items()}}
        summary["wall_seconds"]["shell_strips_like_swatch"] = float(sum(part[1] for part in parts))
        summary["shell_vs_yarn"] = {
            "same_proportions": compare_shell_yarn(like, summary["scenes"]["yarn"], strip="swatch"),
            "fab_8x5": compare_shell_yarn(summary["scenes"]["stretch"], summary["scenes"]["yarn"]),
            "shell_strips": like["strips"],
        }
    summary["verdicts"] = [verdict.to_dict() for verdict in verdicts(summary, file.family)]
    path = folder / "summary.json"
    path.write_text(json.dumps(jsonable(summary), indent=2) + "\n")
    return summary, path


def shell_strips_like_swatch(material, yarn: dict, *, quick: bool = False) -> dict:
    """The fitted shell in the yarn swatch's own test: per yarn direction, a strip of its membrane
    with the swatch's gauge and width between the same jaws, pulled quasi-statically to the
    swatch's strains and read as it is (:func:`yarnfit.validate.shell_strip.shell_strip_limit`,
    meshed along the yarns, extrapolated to a fine mesh from :data:`LIKE_SWATCH_ROWS`); in the
    stretch summary's form, strips named ``swatch_<direction>`` (``quasi_static`` true), each
    with the middle's readings beside the jaws'.

    Why not MuJoCo strips of the swatch's proportions (as until session 49): a clamped strip's
    pull depends on its proportions and on its jaws, which these keep, and a MuJoCo strip adds its
    mesh's locking (bias strips on a mesh that does not follow the yarns, ``docs/design.md`` §7)
    and its settling to the shell's own error; the MuJoCo cloth is judged on its own in the
    stretch scene."""
    from .shell_strip import shell_strip_limit

    out = {"strips": {}}
    for direction, curve in yarn.get("directions", {}).items():
        strains = [float(e) for e in curve["strain"] if e > 0.0]
        strip = shell_strip_limit(material.shell, curve["angle_deg"], curve["gauge_m"], curve["width_m"], strains,
                                  rows=LIKE_SWATCH_ROWS[quick])
        states = [strip.at_strain(e) for e in strains]
        out["strips"][f"swatch_{direction}"] = {
            "quasi_static": True,
            "length_m": strip.gauge,
            "width_m": strip.width,
            "angle_rad": math.radians(strip.angle_deg),
            "rows": list(strip.rows),
            "strain": strains,
            "force_per_width_n_per_m": [s.force_n_per_m for s in states],
            "compression_ratio": [s.compression_ratio for s in states],
            "middle_force_n_per_m": [s.middle_force_n_per_m for s in states],
            "mid_strain": [s.mid_strain for s in states],
            "middle_compression_ratio": [s.middle_compression_ratio for s in states],
            "converged": [s.converged for s in states],
            # The same shell pulled free at the jaws' strains: how far the jaws hold its strip.
            "free_pull_n_per_m": [material.shell.uniaxial_pull(math.radians(strip.angle_deg), 1.0 + e).force_n_per_m
                                  for e in strains],
        }
    return out


def compare_shell_yarn(stretch: dict, yarn: dict, strip: str = "8x5") -> dict:
    """The shell's ``<strip>_<direction>`` strips against the explicit yarn swatch, per direction, at the yarn
    test's strains: ``strain``, ``shell_force_n_per_m`` and ``shell_compression_ratio`` (the shell
    curve interpolated there), ``yarn_force_n_per_m``, ``yarn_compression_ratio`` and
    ``force_relative_difference`` (shell / yarn − 1; the issue's target is within 20 % up to 10 %),
    and where the strip carries the shell pulled free (``free_pull_n_per_m``,
    :func:`shell_strips_like_swatch`) ``jaws_hold``, the strip's force over the free pull's: how
    far the jaws, not the material, set the reading (a bias strip shorter than about twice its
    width holds a woven's shell several times its free pull). Strains outside the shell's pulled
    range are left out."""
    import numpy as np

    out = {}
    for direction, curve in yarn.get("directions", {}).items():
        strip_curve = stretch.get("strips", {}).get(f"{strip}_{direction}")
        if strip_curve is None:
            continue
        shell_strain = np.asarray(strip_curve["strain"])
        strain = np.asarray(curve["strain"], float)
        # The shell's measured strains fall ~1 % short of their nominal levels (the servo's lag), so
        # the last segment is extended by SHELL_RANGE_SLACK to reach a yarn point at the same level.
        top = shell_strain[-1] * (1 + SHELL_RANGE_SLACK)
        inside = (strain >= shell_strain[0]) & (strain <= top)
        shell_force = _interp_extend(strain[inside], shell_strain, strip_curve["force_per_width_n_per_m"])
        yarn_force = np.asarray(curve["force_n_per_m"], float)[inside]
        out[direction] = {
            "strain": strain[inside].tolist(),
            "shell_force_n_per_m": shell_force.tolist(),
            "yarn_force_n_per_m": yarn_force.tolist(),
            "shell_compression_ratio": _interp_extend(strain[inside], shell_strain, strip_curve["compression_ratio"]).tolist(),
            "yarn_compression_ratio": np.asarray(curve["compression_ratio"], float)[inside].tolist(),
            "force_relative_difference": (shell_force / yarn_force - 1.0).tolist(),
        }
        if "free_pull_n_per_m" in strip_curve:
            free = _interp_extend(strain[inside], shell_strain, strip_curve["free_pull_n_per_m"])
            out[direction]["jaws_hold"] = [float(a / b) if b > 0.0 else None for a, b in zip(shell_force, free)]
    return out


def _interp_extend(x, xp, fp):
    """Linear interpolation, continued linearly beyond the last point."""
    import numpy as np

    xp, fp = np.asarray(xp, float), np.asarray(fp, float)
    y = np.interp(x, xp, fp)
    beyond = x > xp[-1]
    if beyond.any() and len(xp) > 1:
        slope = (fp[-1] - fp[-2]) / (xp[-1] - xp[-2])
        y[beyond] = fp[-1] + slope * (x[beyond] - xp[-1])
    return y
