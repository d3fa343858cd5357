"""One-flex garments cut from 2D panels (issue 15, item 3).

A garment is one 2D flex whose **rest shape is its panels' pattern**, not its ``qpos0`` shape:
each panel is a flat triangulated piece of cloth in its own 2D pattern frame (m) with its own grain
(the weft direction in that frame), and seams merge the vertices of panel edges cut to the same
length. MuJoCo holds the pattern as the flex's texture coordinates, one pair per triangle corner
(``texcoord`` + ``elemtexcoord``): a corner's coordinates are its **material coordinates** in its
panel (m; weft along the first axis), so a seam vertex has one position but a different pattern
point in each panel it joins, and every panel has its own grain. The ``yarnfit.shell`` plugin with
``rest="texcoord"`` takes each triangle's rest metric and material axes from those corners; the
3D positions at ``qpos0`` only say where the garment starts (around a body, say), and need not be
flat or unstrained.

MuJoCo's built-in ``<elasticity>`` (the implicit isotropic share of the split,
:mod:`yarnfit.mujoco.split`) computes its rest from ``qpos0`` when the model compiles: its rest edge
lengths (``mjModel.flexedge_length0``), per-triangle membrane metric (``flex_stiffness``) and
per-hinge bending operator (``flex_bending``, with a curved-reference term for a bent ``qpos0``).
:func:`use_pattern_rest` rewrites the three from the texture coordinates, as MuJoCo's compiler
would have computed them for the flat pattern (checked against its compiled values for flat
panels), before ``mjData`` is made; MuJoCo reads them at every step, so its implicit share then
pulls towards the pattern too. The plugin checks them at init and refuses to step a garment whose
built-in part still has the ``qpos0`` rest.

Texture coordinates are float32 in MuJoCo: pattern points up to a metre from the panel's origin
are held to ~6e-8 m, a rest strain below 1e-5 on centimetre cells, far below any strain cloth
shows.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from .split import isotropic_stiffness

__all__ = ["Garment", "Panel", "Seam", "builtin_bending_operator", "builtin_membrane_metric", "membrane_metric", "sew",
           "use_pattern_rest"]

# Relative disagreement allowed between the two panels' lengths of a seam edge (both cut from the
# pattern, so they agree to float32 round-off, ~1e-7): MuJoCo keeps one rest length per edge and
# use_pattern_rest gives it their mean. The plugin checks the same bound (YF_PATTERN_LENGTH_RTOL).
SEAM_LENGTH_RTOL = 1e-5


@dataclass(frozen=True)
class Panel:
    """A flat piece of a garment: ``points (n, 2)`` in its pattern frame (m), ``triangles (m, 3)``
    counter-clockwise in that frame, ``grain`` the weft direction's angle from the frame's first
    axis (rad; π/4 cuts the panel on the bias), and ``placement (n, 3)``, where each point starts
    in 3D (m)."""

    name: str
    points: np.ndarray
    triangles: np.ndarray
    placement: np.ndarray
    grain: float = 0.0

    def __post_init__(self):
        points, triangles, placement = (np.asarray(self.points, float), np.asarray(self.triangles, int),
                                        np.asarray(self.placement, float))
        if points.ndim != 2 or points.shape[1] != 2:
            raise ValueError(f"panel {self.name!r}: points must be (n, 2), got {points.shape}")
        if placement.shape != (len(points), 3):
            raise ValueError(f"panel {self.name!r}: placement must be ({len(points)}, 3), got {placement.shape}")
        if triangles.ndim != 2 or triangles.shape[1] != 3 or triangles.min() < 0 or triangles.max() >= len(points):
            raise ValueError(f"panel {self.name!r}: triangles must be (m, 3) indices into its {len(points)} points")
        if not math.isfinite(self.grain):
            raise ValueError(f"panel {self.name!r}: grain must be finite, got {self.grain}")
        object.__setattr__(self, "points", points)
        object.__setattr__(self, "triangles", triangles)
        object.__setattr__(self, "placement", placement)

    def material_points(self) -> np.ndarray:
        """``(n, 2)`` material coordinates (m): the pattern turned so that the weft is the first axis."""
        c, s = math.cos(self.grain), math.sin(self.grain)
        return self.points @ np.array([[c, -s], [s, c]])


@dataclass(frozen=True)
class Seam:
    """Panel ``a``'s vertices ``vertices_a`` sewn one-to-one onto panel ``b``'s ``vertices_b`` (in
    order along the seam; the two polylines must have the same edge lengths)."""

    a: str
    vertices_a: np.ndarray
    b: str
    vertices_b: np.ndarray


@dataclass(frozen=True)
class Garment:
    """Panels sewn into one mesh: ``points (V, 3)`` the start positions (m; a seam vertex at the
    mean of its panels' placements), ``triangles (T, 3)``, ``corner_uv (T, 3, 2)`` each triangle
    corner's material coordinates in its panel (m), ``panel_of_triangle (T,)`` indices into
    ``panel_names``, ``seam_vertices`` the merged vertices."""

    points: np.ndarray
    triangles: np.ndarray
    corner_uv: np.ndarray
    panel_of_triangle: np.ndarray
    panel_names: tuple[str, ...]
    seam_vertices: np.ndarray

    def rest_areas(self) -> np.ndarray:
        """``(T,)`` pattern areas (m²)."""
        e1 = self.corner_uv[:, 1] - self.corner_uv[:, 0]
        e2 = self.corner_uv[:, 2] - self.corner_uv[:, 0]
        return 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])


def sew(panels: list[Panel], seams: list[Seam]) -> Garment:
    """Merge the panels' seam vertices into one mesh (vertices numbered panel by panel, each seam
    vertex kept once). Raises ``ValueError`` for unknown panels, seams of unequal vertex counts or
    edge lengths (beyond :data:`SEAM_LENGTH_RTOL`), and non-manifold results (an edge in more than two
    triangles)."""
    names = [p.name for p in panels]
    if len(set(names)) != len(names):
        raise ValueError(f"panel names must be unique, got {names}")
    index = {p.name: i for i, p in enumerate(panels)}
    offsets = np.cumsum([0] + [len(p.points) for p in panels])
    parent = np.arange(offsets[-1])

    def root(v: int) -> int:
        while parent[v] != v:
            parent[v] = parent[parent[v]]
            v = parent[v]
        return v

    for seam in seams:
        for name in (seam.a, seam.b):
            if name not in index:
                raise ValueError(f"seam names an unknown panel {name!r}; panels: {', '.join(names)}")
        pa, pb = panels[index[seam.a]], panels[index[seam.b]]
        va, vb = np.asarray(seam.vertices_a, int), np.asarray(seam.vertices_b, int)
        if va.shape != vb.shape or va.ndim != 1 or len(va) < 2:
            raise ValueError(f"seam {seam.a}-{seam.b}: needs two equally long vertex lists of at least 2, "
                             f"got {va.shape} and {vb.shape}")
        la = np.linalg.norm(np.diff(pa.points[va], axis=0), axis=1)
        lb = np.linalg.norm(np.diff(pb.points[vb], axis=0), axis=1)
        worst = float(np.max(np.abs(la - lb) / la))
        if worst > SEAM_LENGTH_RTOL:
            raise ValueError(f"seam {seam.a}-{seam.b}: its edges differ in length by up to {100 * worst:.3g} % "
                             f"between the panels (at most {100 * SEAM_LENGTH_RTOL:g} %): cut both sides alike")
        for a, b in zip(va + offsets[index[seam.a]], vb + offsets[index[seam.b]]):
            ra, rb = root(int(a)), root(int(b))
            parent[max(ra, rb)] = min(ra, rb)
    roots = np.array([root(v) for v in range(offsets[-1])])
    kept, new_index = np.unique(roots, return_inverse=True)
    placement = np.vstack([p.placement for p in panels])
    points = np.zeros((len(kept), 3))
    np.add.at(points, new_index, placement)
    points /= np.bincount(new_index)[:, None]
    triangles = np.vstack([new_index[p.triangles + offsets[i]] for i, p in enumerate(panels)])
    corner_uv = np.concatenate([p.material_points()[p.triangles] for p in panels])
    panel_of_triangle = np.concatenate([np.full(len(p.triangles), i) for i, p in enumerate(panels)])
    edges = np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]), axis=1)
    _, count = np.unique(edges, axis=0, return_counts=True)
    if count.max() > 2:
        raise ValueError("the sewn garment has an edge shared by more than two triangles: a seam sews a panel "
                         "edge twice")
    merged = np.bincount(new_index) > 1
    return Garment(points, triangles, corner_uv, panel_of_triangle, tuple(names), np.flatnonzero(merged))


def _corner_uv(model: mujoco.MjModel, f: int) -> np.ndarray:
    """``(T, 3, 2)`` the flex's texture coordinates per triangle corner, in double."""
    if model.flex_texcoordadr[f] < 0:
        raise ValueError(f"flex {f} has no texture coordinates")
    elems = model.flex_elemnum[f]
    corner = model.flex_elemtexcoord[model.flex_elemdataadr[f]:model.flex_elemdataadr[f] + 3 * elems]
    uv = model.flex_texcoord[model.flex_texcoordadr[f]:].astype(float)
    return uv[corner].reshape(elems, 3, 2)


def membrane_metric(corner_uv: np.ndarray, elem_edge_local: np.ndarray, stiffness: np.ndarray,
                    thickness: float) -> np.ndarray:
    """The per-triangle membrane metric of MuJoCo's ``flex_stiffness`` for a flat rest ``corner_uv
    (T, 3, 2)`` (m) and a membrane ``stiffness (3, 3)`` (Pa, Voigt strain ``(E00, E11, 2 E01)`` in
    the frame of ``corner_uv``) of ``thickness`` (m): ``(T, 6)``, the upper triangle of ``K_ab = 2 A
    t g_aᵀ C g_b`` over the triangle's edges in ``flex_elemedge`` order (``elem_edge_local (T, 3)``:
    the local edge, vertices k → k+1, of each slot), ``g_k`` the Voigt Green strain per unit squared
    length of edge k (``G_k = ∂E/∂(l_k²)``), so that the energy ``¼ Δᵀ K Δ``, ``Δ_a = l_a² − L_a²``,
    is ``A t ½ εᵀ C ε``. MuJoCo compiles the isotropic one (:func:`builtin_membrane_metric`); the
    plugin's ``implicit_share`` writes an anisotropic one (plugins/README.md, Split)."""
    D = np.stack([corner_uv[:, 1] - corner_uv[:, 0], corner_uv[:, 2] - corner_uv[:, 0]], axis=2)  # columns e1, e2
    Dinv = np.linalg.inv(D)
    area = 0.5 * np.abs(np.linalg.det(D))
    # XᵀX = [[l01², e1·e2], [e1·e2, l02²]] with e1·e2 = (l01² + l02² − l12²)/2; its derivative by
    # each squared edge length (local edges 01, 12, 20):
    dC = np.array([[[1, 0.5], [0.5, 0]], [[0, -0.5], [-0.5, 0]], [[0, 0.5], [0.5, 1]]])
    G = 0.5 * np.einsum("tji,kjl,tlm->tkim", Dinv, dC, Dinv)  # (T, 3, 2, 2): ½ D⁻ᵀ dC_k D⁻¹
    G = G[np.arange(len(G))[:, None], elem_edge_local]  # slot order
    g = np.stack([G[..., 0, 0], G[..., 1, 1], G[..., 0, 1] + G[..., 1, 0]], axis=-1)  # (T, 3, 3): g per slot
    metric = [2 * area * thickness * np.einsum("ti,ij,tj->t", g[:, a], stiffness, g[:, b])
              for a in range(3) for b in range(a, 3)]
    return np.stack(metric, axis=1)


def builtin_membrane_metric(corner_uv: np.ndarray, elem_edge_local: np.ndarray, young: float, poisson: float,
                            thickness: float) -> np.ndarray:
    """MuJoCo's compiled membrane metric for a flat rest ``corner_uv (T, 3, 2)`` (m): :func:`membrane_metric`
    of the isotropic plane-stress membrane (``young`` Pa, ``poisson``), whose ``½ g_aᵀ C g_b`` is
    MuJoCo's ``μ tr(G_a G_b) + λ*/2 tr G_a tr G_b``, μ = E/(2(1 + ν)), λ* = Eν/(1 − ν²)."""
    return membrane_metric(corner_uv, elem_edge_local, isotropic_stiffness(young, poisson), thickness)


def builtin_bending_operator(diamond: np.ndarray, young: float, poisson: float, thickness: float) -> np.ndarray:
    """MuJoCo's hinge operator for flat diamonds: ``diamond (H, 4, 2)`` (m) the rest positions of each
    interior edge's vertices (edge v0, v1, flap 2, flap 3, the flaps on opposite sides), returns
    ``(H, 17)``: the 4 × 4 block ``c cᵀ cosθ · D / (A₁ + A₂)``, ``D = E t³/(12(1 − ν²))`` (MuJoCo's
    bending rigidity, the same E and t as its membrane), with c the cotangent
    weights (Wardetzky et al.'s quadratic bending energy), and 0 for the curved-reference term of
    a flat rest."""
    v = np.concatenate([diamond, np.zeros(diamond.shape[:2] + (1,))], axis=2)

    def cot(a, b, c):  # cotangent of the angle at a in triangle (a, b, c)
        e1, e2 = b - a, c - a
        return np.einsum("hi,hi->h", e1, e2) / np.linalg.norm(np.cross(e1, e2), axis=1)

    v0, v1, v2, v3 = v[:, 0], v[:, 1], v[:, 2], v[:, 3]
    a01, a02, a03, a04 = cot(v0, v1, v2), cot(v0, v3, v1), cot(v1, v2, v0), cot(v1, v0, v3)
    c = np.stack([a03 + a04, a01 + a02, -(a01 + a03), -(a02 + a04)], axis=1)
    area = 0.5 * (np.linalg.norm(np.cross(v1 - v0, v2 - v0), axis=1) + np.linalg.norm(np.cross(v0 - v1, v3 - v1), axis=1))
    stiffness = young * thickness**3 / (12 * (1 - poisson**2)) / area
    t0 = -((v2 - v0) * a03[:, None] + (v2 - v1) * a01[:, None])
    t1 = -((v3 - v0) * a04[:, None] + (v3 - v1) * a02[:, None])
    cos_theta = -np.einsum("hi,hi->h", t0, t1) / np.einsum("hi,hi->h", v1 - v0, v1 - v0)
    out = np.zeros((len(v), 17))
    out[:, :16] = (np.einsum("hi,hj->hij", c, c) * (cos_theta * stiffness)[:, None, None]).reshape(-1, 16)
    return out


def _edge_slots(model: mujoco.MjModel, f: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Flex-local ``triangles (T, 3)``, ``edges (E, 2)``, each triangle's edges in
    ``flex_elemedge`` order ``slots (T, 3)`` and per slot ``j`` its local edge ``k`` (vertices
    k → k+1): ``(T, 3)``."""
    elems = model.flex_elemnum[f]
    triangles = model.flex_elem[model.flex_elemdataadr[f]:model.flex_elemdataadr[f] + 3 * elems].reshape(-1, 3)
    edges = model.flex_edge[model.flex_edgeadr[f]:model.flex_edgeadr[f] + model.flex_edgenum[f]]
    slots = model.flex_elemedge[model.flex_elemedgeadr[f]:model.flex_elemedgeadr[f] + 3 * elems].reshape(-1, 3)
    local = np.full((elems, 3), -1)
    for k in range(3):
        a, b = triangles[:, k], triangles[:, (k + 1) % 3]
        for j in range(3):
            p, q = edges[slots[:, j], 0], edges[slots[:, j], 1]
            local[((p == a) & (q == b)) | ((p == b) & (q == a)), j] = k
    if (local < 0).any():
        raise ValueError(f"flex {f}: an element edge is not an edge of its triangle")
    return triangles, edges, slots, local


def use_pattern_rest(model: mujoco.MjModel, flex: str, young: float, poisson: float, thickness: float) -> None:
    """Rewrite MuJoCo's built-in rest of flex ``flex`` (its ``<elasticity>`` of ``young`` Pa,
    ``poisson``, ``thickness`` m) from its texture coordinates, in place: ``flexedge_length0`` (a seam
    edge gets the mean of its two panels' lengths), ``flex_stiffness`` (:func:`builtin_membrane_metric`)
    and ``flex_bending`` (:func:`builtin_bending_operator`, each hinge's two triangles unfolded into
    one plane by their pattern edge lengths). Call it after compiling and before ``mujoco.MjData``.
    Raises ``ValueError`` if a seam edge's two lengths differ by more than :data:`SEAM_LENGTH_RTOL`."""
    f = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_FLEX, flex)
    if f < 0:
        raise ValueError(f"no flex named {flex!r}")
    if model.flex_dim[f] != 2:
        raise ValueError(f"flex {flex!r} has dim {model.flex_dim[f]}; a garment is a 2D flex")
    uv = _corner_uv(model, f)
    triangles, edges, slots, local = _edge_slots(model, f)
    # Each triangle's pattern length of each edge, per flex edge (one or two of them).
    k1 = (local + 1) % 3
    rows = np.arange(len(triangles))[:, None]
    lengths = np.linalg.norm(uv[rows, k1] - uv[rows, local], axis=2)
    total = np.bincount(slots.ravel(), lengths.ravel(), minlength=len(edges))
    count = np.bincount(slots.ravel(), minlength=len(edges))
    mean = total / np.maximum(count, 1)
    spread = np.abs(lengths - mean[slots]) / mean[slots]
    if spread.max() > 0.5 * SEAM_LENGTH_RTOL:
        t, j = np.unravel_index(int(spread.argmax()), spread.shape)
        raise ValueError(f"flex {flex!r}: edge {slots[t, j]} is {lengths[t, j]:.9g} m in one panel and differs from "
                         f"its other side by {200 * spread[t, j]:.3g} % (at most {100 * SEAM_LENGTH_RTOL:g} %)")
    adr = model.flex_edgeadr[f]
    model.flexedge_length0[adr:adr + len(edges)] = mean
    if model.flex_stiffnessadr[f] >= 0:
        start = model.flex_stiffnessadr[f]
        block = model.flex_stiffness[start:start + 21 * len(triangles)].reshape(-1, 21)
        block[:, :6] = builtin_membrane_metric(uv, local, young, poisson, thickness)
    if model.flex_bendingadr[f] >= 0:
        flaps = model.flex_edgeflap[adr:adr + len(edges)]
        interior = np.flatnonzero((flaps[:, 0] >= 0) & (flaps[:, 1] >= 0))
        corner_of = {}
        for t, tri in enumerate(triangles):
            for k in range(3):
                corner_of[(frozenset(tri), int(tri[k]))] = uv[t, k]
        diamond = np.zeros((len(interior), 4, 2))
        for h, e in enumerate(interior):
            v0, v1 = (int(v) for v in edges[e])
            length = mean[e]
            diamond[h, 1] = (length, 0.0)
            for side, flap in enumerate(flaps[e]):
                key = frozenset((v0, v1, int(flap)))
                p0, p1, po = corner_of[(key, v0)], corner_of[(key, v1)], corner_of[(key, int(flap))]
                a, b = np.linalg.norm(po - p0), np.linalg.norm(po - p1)
                along = (a * a - b * b + length * length) / (2 * length)
                diamond[h, 2 + side] = (along, (1 - 2 * side) * math.sqrt(max(a * a - along * along, 0.0)))
        start = model.flex_bendingadr[f]
        block = model.flex_bending[start:start + 17 * len(edges)].reshape(-1, 17)
        block[interior] = builtin_bending_operator(diamond, young, poisson, thickness)
