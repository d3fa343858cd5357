"""The validation suite (``yarnfit validate``, issue 6): a fitted material in FAB-style stretch
tests, against an explicit yarn-level swatch, in sphere, wall and Cusick drapes and in garments on a
moving body, each scene recorded to ``logs/<material>/<scene>.rrd`` and summarised in ``summary.json``.

One module per scene, each of one shape: build the scene, run it, return a typed result (a
:class:`SceneResult`), record it through a :class:`yarnfit.record.Recording`. Each exposes
``run_<scene>(material, *, quick=False, recording_path=None, progress=None)``; the result's
:meth:`~SceneResult.summary` is the scene's entry of ``summary.json`` (keys carry their units, SI;
values are JSON numbers, lists or dicts). This file imports nothing heavy: the command line builds
its parser from it.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

# The scenes of yarnfit.validate.drape.
DRAPES = ("sphere", "wall", "cusick")
SCENES = ("stretch", "yarn", *DRAPES, "body")
# The directions a strip is pulled in: the pull axis's angle from the weft, in degrees.
DIRECTIONS = {"weft": 0.0, "warp": 90.0, "bias": 45.0}
# ... and the directions a shell's and a repeat's own pulls are reported in: those and the other
# bias, which a woven's twill or satin line makes differ from the first (the suite's strips are cut
# along +45° only; validation/swatch_convergence.py cuts a strip along any of these).
PULL_DIRECTIONS = {**DIRECTIONS, "other bias": -45.0}

# Field metadata of a SceneResult: left out of the summary (arrays kept for callers), or left out
# while None (a figure only some variants of a scene have).
NOT_SUMMARISED = {"summary": False}
OPTIONAL = {"optional": True}


class SceneResult:
    """Base of every scene's result (a dataclass): typed fields, and :meth:`summary`, the JSON
    dict ``summary.json`` carries: every field in order, but those marked :data:`NOT_SUMMARISED`
    and :data:`OPTIONAL` ones that are None."""

    def summary(self) -> dict:
        out = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if not f.metadata.get("summary", True) or (f.metadata.get("optional") and value is None):
                continue
            out[f.name] = jsonable(value)
        return out


def jsonable(value):
    """``value`` with scene results summarised, NumPy arrays and scalars as lists and numbers and
    paths as strings, recursively through dicts, lists and tuples (anything else as it is)."""
    if isinstance(value, SceneResult):
        return value.summary()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, dict):
        return {k: jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    return value
