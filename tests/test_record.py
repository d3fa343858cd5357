"""Rerun recordings of relaxations: the ``.rrd`` file holds every documented entity path on the
``iteration`` timeline, the yarn strips close across the tile border, and the timeline counts on
across relaxations. The file is read back with ``rerun.chunk.RrdReader`` (no viewer, no network).
"""

import dataclasses
import re

import numpy as np
import pytest
import rerun as rr

import yarnfit.record
from yarnfit.engine import Progress, Residual
from yarnfit.fibers import get_fiber
from yarnfit.patterns import DRAFTS, weave
from yarnfit.record import RelaxRecording
from yarnfit.relax import relax_pattern

# Strips are stored as float32; positions are ~1e-3 m, so float32 round-off is ~1e-10 m.
POSITION_TOLERANCE = 1e-9  # m

PER_NODE_FIELDS = ("node_position", "node_twist", "rest_length", "rest_curvature", "rest_twist",
                   "reference_director", "reference_twist")


def plain_weave(radius=8e-5):
    return weave(DRAFTS["plain"], 3000.0, 3000.0, radius)


def shuffled(pattern, seed=0):
    """The same pattern with its nodes renumbered at random, so that yarn order (the order of
    progress positions) differs from node index order."""
    new_index = np.random.default_rng(seed).permutation(pattern.n_nodes)

    def move(values):
        out = np.empty_like(values)
        out[new_index] = values
        return out

    edges = pattern.edges.copy()
    edges[:, :2] = new_index[edges[:, :2]]
    result = dataclasses.replace(pattern, edges=edges, **{key: move(getattr(pattern, key)) for key in PER_NODE_FIELDS})
    result.validate()
    return result


def yarn_order(pattern):
    """Node positions in yarn order, as the solver reports them ``(N, 3)`` m."""
    return np.concatenate([pattern.node_position[y.nodes] for y in pattern.yarns()])


def expected_strips(pattern, position):
    """Closed strip per yarn: its nodes, then its first node moved by its net tile offset."""
    strips, start = [], 0
    for y in pattern.yarns():
        points = position[start:start + len(y.nodes)]
        start += len(y.nodes)
        closing = points[0] + np.array(y.net_offset, dtype=float) @ pattern.lattice
        strips.append(np.vstack([points, closing]))
    return strips


def fake_progress(iteration, position):
    residual = Residual(force=10.0 ** -iteration, torque=0.5 * 10.0 ** -iteration, energy_change=0.0,
                        penetration=1e-3)
    return Progress(iteration, residual, position, potential=1e-6 / iteration)


def read_back(path):
    """Rows of the recording in ``path``: ``{entity_path: {component: {iteration: value}}}`` for
    temporal data (``None`` as the iteration for static data), plus the chunks' timeline names."""
    reader = rr.chunk.RrdReader(path)
    rows, timelines = {}, {}
    for chunk in reader.stream():
        batch = chunk.to_record_batch()
        names = [n for n in batch.schema.names if ":" in n]
        steps = batch.column("iteration").to_pylist() if "iteration" in batch.schema.names else [None] * batch.num_rows
        for name in names:
            for step, value in zip(steps, batch.column(name).to_pylist()):
                rows.setdefault(chunk.entity_path, {}).setdefault(name, {})[step] = value
        timelines.setdefault(chunk.entity_path, set()).update(chunk.timeline_names)
    return reader, rows, timelines


def documented_paths():
    """Entity paths listed in the module docstring (the README quotes it)."""
    return set(re.findall(r"``(relax(?:/\w+)*)``", yarnfit.record.__doc__))


def test_strips_close_across_the_tile_and_the_timeline_counts_on(tmp_path):
    pattern = shuffled(plain_weave())
    bigger = dataclasses.replace(pattern, radius=1.25 * pattern.radius)  # a second relaxation, new radius
    path = tmp_path / "sub" / "fake.rrd"
    recording = RelaxRecording("fake relaxation", path)
    rng = np.random.default_rng(1)
    moved = {}  # timeline step -> positions logged there
    for r, relaxation in enumerate((pattern, bigger)):
        recording.start(relaxation)
        for iteration in (1, 2, 3):
            position = yarn_order(relaxation) + 1e-5 * rng.standard_normal((relaxation.n_nodes, 3))
            recording(fake_progress(iteration, position))
            moved[4 * r + iteration] = position
    recording.close()

    assert path.is_file() and path.stat().st_size > 0
    _, rows, _ = read_back(path)
    # start() at 0 and 4, Newton iterations at 1-3 and 5-7: one counter across both relaxations.
    assert sorted(rows["/relax/residual/force"]["Scalars:scalars"]) == [1, 2, 3, 5, 6, 7]
    assert sorted(rows["/relax/repeat/yarns"]["LineStrips3D:radii"]) == [0, 4]
    assert rows["/relax/repeat/yarns"]["LineStrips3D:radii"][4] == [pytest.approx(bigger.radius)]
    assert rows["/relax/residual/force"]["Scalars:scalars"][6] == [pytest.approx(1e-2)]

    strips = rows["/relax/repeat/yarns"]["LineStrips3D:strips"]
    tiling = rows["/relax/tiling/yarns"]["LineStrips3D:strips"]
    n_yarns = len(pattern.yarns())
    for step, position in [(0, yarn_order(pattern))] + sorted(moved.items()):
        expected = expected_strips(pattern, position)
        assert len(strips[step]) == n_yarns and len(tiling[step]) == 9 * n_yarns
        for got, want in zip(strips[step], expected):
            np.testing.assert_allclose(np.array(got), want, atol=POSITION_TOLERANCE)
        # Tile t = (i, j) with i, j in {-1, 0, 1}, i slowest, holds the strips moved by i a0 + j a1.
        shifts = [i * pattern.lattice[0] + j * pattern.lattice[1] for i in (-1, 0, 1) for j in (-1, 0, 1)]
        for t, shift in enumerate(shifts):
            for k, want in enumerate(expected):
                np.testing.assert_allclose(np.array(tiling[step][t * n_yarns + k]), want + shift,
                                           atol=POSITION_TOLERANCE)

    colors = np.array(rows["/relax/tiling/yarns"]["LineStrips3D:colors"][0]).reshape(9, n_yarns)
    centre, neighbours = colors[4], np.delete(colors, 4, axis=0)
    assert not set(centre) & set(neighbours.ravel())


def test_relaxations_record_every_documented_entity(tmp_path):
    fiber = get_fiber("cotton")
    pattern = plain_weave()
    path = tmp_path / "relax.rrd"
    recording = RelaxRecording("plain cotton", path)
    calls = 0

    def progress(p):
        nonlocal calls
        calls += 1
        recording(p)

    # Two relaxations at different radii, as relax() runs them while it refines the radius.
    for radius in (8e-5, 9e-5):
        relaxation = pattern.scaled(pattern.repeat_size, radius)
        recording.start(relaxation)
        result = relax_pattern(relaxation, fiber, on_iteration=progress)
    recording.finish(result)

    assert path.is_file() and path.stat().st_size > 0
    reader, rows, timelines = read_back(path)
    assert [s.application_id for s in reader.recordings()] == ["yarnfit"]
    assert reader.blueprints(), "the recording should carry its viewer layout"
    assert rows["/__properties"]["RecordingInfo:name"][None] == ["plain cotton"]

    documented = documented_paths()
    assert {"relax/repeat/yarns", "relax/tiling/yarns", "relax/residual/force", "relax/residual/torque",
            "relax/residual/penetration", "relax/residual/energy_change", "relax/energy/potential",
            "relax/energy/total", "relax/summary"} <= documented
    recorded = {p.lstrip("/") for p in rows} - {"__properties"}
    assert recorded == documented
    for entity in documented - {"relax"}:  # "relax" holds only static view coordinates
        assert yarnfit.record.TIMELINE in timelines["/" + entity], entity

    # One step per start, per Newton iteration and for finish, never reset.
    last = 2 + calls
    assert sorted(rows["/relax/summary"]["TextDocument:text"]) == [last]
    assert max(rows["/relax/repeat/yarns"]["LineStrips3D:strips"]) == last
    assert len(rows["/relax/energy/potential"]["Scalars:scalars"]) == calls
    assert rows["/relax/energy/total"]["Scalars:scalars"][last] == [pytest.approx(result.energy.total)]
    text = rows["/relax/summary"]["TextDocument:text"][last][0]
    assert "g/m²" in text and "converged | yes" in text
