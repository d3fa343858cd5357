"""Stepping a scene and reporting whether it stayed stable, and how fast it ran.

MuJoCo does not stop on a divergence: when an acceleration is not finite or exceeds its limit it
raises the bad-QACC warning, resets the data and carries on (``docs/design.md`` §7). So
:func:`run_scene` counts that warning, checks positions for non-finite values, and stops at the
first sign of either.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from .scenes import compile_quietly

__all__ = ["RunReport", "load_model", "run_scene"]


@dataclass(frozen=True)
class RunReport:
    """What :func:`run_scene` saw.

    Attributes:
        steps: steps taken (fewer than asked if the run became unstable).
        simulated_s: simulated time reached (s).
        ms_per_step: wall time per step (ms), model compilation excluded.
        bad_qacc: count of MuJoCo's bad-QACC warnings (each one reset the data).
        nonfinite: True if a position became NaN or infinite.
        max_speed: largest vertex speed seen (m/s), over all steps.
        timestep: Δt (s).
        integrator: the model's integrator, as MJCF spells it.
    """

    steps: int
    simulated_s: float
    ms_per_step: float
    bad_qacc: int
    nonfinite: bool
    max_speed: float
    timestep: float
    integrator: str

    @property
    def stable(self) -> bool:
        return self.bad_qacc == 0 and not self.nonfinite

    def __str__(self) -> str:
        state = "stable" if self.stable else f"UNSTABLE (bad QACC {self.bad_qacc}, non-finite {self.nonfinite})"
        return (f"{self.steps} steps of {self.timestep:g} s ({self.integrator}), {self.ms_per_step:.3g} ms/step, "
                f"max |v| {self.max_speed:.3g} m/s, {state}")


def load_model(source: mujoco.MjModel | mujoco.MjSpec | str | os.PathLike) -> mujoco.MjModel:
    """A model from an MJCF path, an ``MjSpec`` (compiled here) or an ``MjModel`` (as is)."""
    if isinstance(source, mujoco.MjModel):
        return source
    if isinstance(source, mujoco.MjSpec):
        return compile_quietly(source)
    if isinstance(source, (str, os.PathLike)):
        return compile_quietly(mujoco.MjSpec.from_file(str(Path(source))))
    raise TypeError(f"expected an MJCF path, an MjSpec or an MjModel, got {type(source).__name__}")


def run_scene(source: mujoco.MjModel | mujoco.MjSpec | str | os.PathLike, seconds: float) -> RunReport:
    """Step a scene for ``seconds`` of simulated time and report its stability and speed.

    A scene with the stretch test's ``pull`` actuator has its control ramped linearly from 0 to
    the top of its range over the run (a quasi-static pull), so the run exercises the strip.

    Args:
        source: an MJCF path, an ``MjSpec`` or an ``MjModel``.
        seconds: simulated time (s), > 0.
    """
    if not (isinstance(seconds, (int, float)) and math.isfinite(seconds) and seconds > 0):
        raise ValueError(f"seconds must be a positive number, got {seconds!r}")
    model = load_model(source)
    data = mujoco.MjData(model)
    steps = max(1, round(seconds / model.opt.timestep))
    pull = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, "pull")
    target = model.actuator_ctrlrange[pull, 1] if pull >= 0 else 0.0
    # Vertex speeds: every flex vertex body with its own three slide dofs.
    bodies = np.unique(model.flex_vertbodyid)
    bodies = bodies[model.body_dofnum[bodies] == 3]
    dofs = model.body_dofadr[bodies][:, None] + np.arange(3)
    warning = int(mujoco.mjtWarning.mjWARN_BADQACC)
    max_speed, nonfinite, taken = 0.0, False, 0
    start = time.perf_counter()
    for step in range(steps):
        if pull >= 0:
            data.ctrl[pull] = target * (step + 1) / steps
        mujoco.mj_step(model, data)
        taken += 1
        if data.warning[warning].number > 0:
            break
        if not np.all(np.isfinite(data.qpos)):
            nonfinite = True
            break
        if len(dofs):
            max_speed = max(max_speed, float(np.sqrt((data.qvel[dofs] ** 2).sum(axis=1)).max()))
    elapsed = time.perf_counter() - start
    names = {int(v): k.removeprefix("mjINT_").lower() for k, v in mujoco.mjtIntegrator.__members__.items()}
    return RunReport(steps=taken, simulated_s=taken * model.opt.timestep, ms_per_step=1e3 * elapsed / taken,
                     bad_qacc=int(data.warning[warning].number), nonfinite=nonfinite, max_speed=max_speed,
                     timestep=float(model.opt.timestep), integrator=names.get(int(model.opt.integrator), "?"))
