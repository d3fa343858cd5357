"""Where a yarn strip's pull stands after a load step, in a file it resumes from
(:func:`yarnfit.validate.swatch.stretch_swatch`'s ``checkpoint``).

A large strip takes hours a strain level on one core (``docs/design.md`` §3: the satin's 8 × 6
strips, 36k nodes, more than two hours for their 5 % level), longer than a session or a laptop's
battery. After every load step the pull writes its state here: the rods' configuration, the
contact set (pairs, multipliers, penalties), the levels finished (their points and node
positions) and the level in progress (its steps' readings and totals). Run again with the same
file, the pull starts from the last step written and lands where an uninterrupted pull lands (the
next step starts from the same state, contacts and strain; test).

One file (NumPy ``.npz``, no pickles) per pull: ``meta`` (JSON text: the format, the pull's
fingerprint, where it stands, the finished points and the level's totals), ``state.<field>`` for
each :class:`~yarnfit.engine.RodState` array, ``contacts.<field>`` and ``contacts.pairs.<field>``
for the :class:`~yarnfit.engine.contact_lagrangian.ContactSet` (absent before the first contact
set), and ``level_positions`` ``(levels finished, N, 3)`` (m). The fingerprint is a hash of the
strip's rod model, rest positions and jaws, the pull's strains, friction, load step and solver
options and the yarnfit version: a checkpoint of another pull, or of a yarnfit whose results
differ, is refused, not resumed.
"""

from __future__ import annotations

import dataclasses
import hashlib
import io
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import __version__
from ..engine import QuasiStaticOptions, RodState
from ..engine.contact import ContactPairs
from ..engine.contact_lagrangian import ContactSet
from ..outputs import write_atomically
from .strip import Swatch

# The file's format; a file of another format is refused.
CHECKPOINT_FORMAT = "yarnfit-pull-checkpoint/1"

__all__ = ["CHECKPOINT_FORMAT", "CheckpointError", "LevelTotals", "PullCheckpoint", "pull_fingerprint"]


class CheckpointError(ValueError):
    """A checkpoint file that cannot be resumed from (another pull's, another format's, not one)."""


def pull_fingerprint(swatch: Swatch, strains: list[float], options: QuasiStaticOptions, width_band: float,
                     friction: float, strain_step: float) -> str:
    """A hash (hex) of what decides a pull's path: the strip (its rod model's arrays, rest positions
    and which nodes each jaw holds), the strains, the width band (m), the friction, the load step,
    the solver's options and the yarnfit version (bumped when a result changes, as for the task
    cache: ``docs/design.md`` §2)."""
    digest = hashlib.sha256()
    model_arrays = [getattr(swatch.model, f.name) for f in dataclasses.fields(swatch.model)]
    for array in [a for a in model_arrays if isinstance(a, np.ndarray)] + [swatch.position, swatch.moving, swatch.fixed]:
        data = np.ascontiguousarray(array)
        digest.update(f"{data.dtype.str}{data.shape}".encode())
        digest.update(data.tobytes())
    digest.update(json.dumps({"version": __version__, "strains": strains, "width_band": width_band, "friction": friction,
                              "strain_step": strain_step, "options": dataclasses.asdict(options)},
                             sort_keys=True).encode())
    return digest.hexdigest()


@dataclass
class LevelTotals:
    """The strain level being pulled, so far: Newton iterations and lagged friction passes over its
    load steps, whether every step converged and settled, the slowest step's and the level's wall
    time (s), and each step's middle reading (as the point's ``steps`` holds them)."""

    iterations: int = 0
    passes: int = 0
    converged: bool = True
    slowest: float = 0.0
    seconds: float = 0.0
    readings: list[dict] = field(default_factory=list)


@dataclass
class PullCheckpoint:
    """A pull after a load step.

    Attributes:
        fingerprint: :func:`pull_fingerprint` of the pull.
        level: the strain level being pulled (1-based, into the pull's strains); one past the last
            when the pull is finished.
        step: load steps of that level done (0 at its start).
        previous: the strain the level starts from.
        points: the finished points (the rest's first), as the curve holds them.
        level_positions: ``(levels finished, N, 3)`` node positions at each finished level (m).
        totals: the level in progress so far (empty at its start).
        state: the rods where the next step starts.
        contacts: their contact set (``None`` before the first solve).
    """

    fingerprint: str
    level: int
    step: int
    previous: float
    points: list[dict]
    level_positions: np.ndarray
    totals: LevelTotals
    state: RodState
    contacts: ContactSet | None

    def write(self, path: str | os.PathLike) -> Path:
        """Write the checkpoint to ``path`` whole or not at all."""
        meta = {"format": CHECKPOINT_FORMAT, "fingerprint": self.fingerprint, "level": self.level, "step": self.step,
                "previous": self.previous, "points": self.points, "totals": dataclasses.asdict(self.totals)}
        arrays = {"meta": np.array(json.dumps(meta)), "level_positions": np.asarray(self.level_positions)}
        arrays.update(_fields("state", self.state))
        if self.contacts is not None:
            arrays.update(_fields("contacts", self.contacts))
        buffer = io.BytesIO()
        np.savez(buffer, **arrays)
        return write_atomically(path, buffer.getvalue())

    @classmethod
    def read(cls, path: str | os.PathLike, fingerprint: str) -> "PullCheckpoint":
        """The checkpoint in ``path``, which must be of the pull whose :func:`pull_fingerprint` is
        ``fingerprint``. Raises :class:`CheckpointError` naming the file otherwise."""
        with np.load(path, allow_pickle=False) as data:
            arrays = {key: data[key] for key in data.files}
        try:
            meta = json.loads(str(arrays.pop("meta")))
        except (KeyError, ValueError) as exc:
            raise CheckpointError(f"{path}: not a pull checkpoint ({exc})") from None
        if meta.get("format") != CHECKPOINT_FORMAT:
            raise CheckpointError(f"{path}: a checkpoint of format {meta.get('format')!r}, not {CHECKPOINT_FORMAT!r}")
        if meta["fingerprint"] != fingerprint:
            raise CheckpointError(f"{path}: the checkpoint of another pull (its strip, strains, friction, load step, "
                                  "solver options or yarnfit version differ): remove it, or give this pull another "
                                  "checkpoint file")
        state = RodState(**{f.name: arrays[f"state.{f.name}"] for f in dataclasses.fields(RodState)})
        contacts = None
        if "contacts.start" in arrays:
            pairs = ContactPairs(**{f.name: arrays[f"contacts.pairs.{f.name}"] for f in dataclasses.fields(ContactPairs)})
            contacts = ContactSet(pairs=pairs, **{f.name: arrays[f"contacts.{f.name}"]
                                                  for f in dataclasses.fields(ContactSet) if f.name != "pairs"})
        return cls(meta["fingerprint"], meta["level"], meta["step"], meta["previous"], meta["points"],
                   arrays["level_positions"], LevelTotals(**meta["totals"]), state, contacts)


def _fields(prefix: str, value) -> dict[str, np.ndarray]:
    """The arrays of the dataclass ``value`` by dotted name (nested dataclasses flattened)."""
    arrays = {}
    for f in dataclasses.fields(value):
        item = getattr(value, f.name)
        if dataclasses.is_dataclass(item):
            arrays.update(_fields(f"{prefix}.{f.name}", item))
        else:
            arrays[f"{prefix}.{f.name}"] = np.asarray(item)
    return arrays
