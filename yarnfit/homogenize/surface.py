"""The relaxed repeat placed on a sample's mid-surface (paper §4.5): the surface map ``φ`` of
``(I, II)``, the per-node rigid maps onto its periodic images (``C_RVE_Γ``), ``C_RVE``, and an
equilibrium carried from one surface to another (see the package docstring)."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial.transform import Rotation

from ..engine import LinearConstraints, RodModel, RodState
from ..engine.contact import ContactPairs, image_range
from ..engine.model import aligned_frames
from ..engine.rotations import as_frames, rotate_frames
from ..engine.tiling import CurvedTiling, retile
from ..relax import RelaxedRepeat, yarn_centroid_constraints
from ..shell import as_first_fundamental_form, as_second_fundamental_form


# A bend whose |det II'| is below this fraction of ‖II'‖² is a cylinder (developable); the
# sample design's bends are exactly singular or far from it.
DEVELOPABLE_TOLERANCE = 1e-12
# Tiles of maps beyond those the rest configuration's contacts reach: contact queries during line
# searches sweep further (the step's length is added to the reach).
EXTRA_TILES = 2


def _spd_sqrt(matrix: np.ndarray) -> np.ndarray:
    """The symmetric square root of a symmetric positive-definite ``(2, 2)`` matrix."""
    w, v = np.linalg.eigh(matrix)
    return (v * np.sqrt(w)) @ v.T


def _form_map(target: np.ndarray, source: np.ndarray) -> np.ndarray:
    """``(3, 3)``: the linear map taking a flat tiling at first form ``source`` to one at
    ``target`` (both ``(2, 2)``), ``√target √source⁻¹`` in the plane. Axis-aligned forms map by
    the exact stretch ratio per axis (an unchanged axis by 1.0): through the general square roots,
    round-off alone sent cotton jersey's 10 % warp pull to another of its equilibria."""
    target, source = np.asarray(target, dtype=np.float64), np.asarray(source, dtype=np.float64)
    matrix = np.eye(3)
    if target[0, 1] == 0.0 and source[0, 1] == 0.0:
        matrix[[0, 1], [0, 1]] = np.sqrt(np.diag(target) / np.diag(source))
    else:
        matrix[:2, :2] = _spd_sqrt(target) @ np.linalg.inv(_spd_sqrt(source))
    return matrix


@dataclass(frozen=True, eq=False)
class SurfaceMap:
    """The deformed mid-surface of one sample: ``φ`` with ``I`` and ``II`` at ``X = 0``."""

    I: np.ndarray
    II: np.ndarray

    def __post_init__(self) -> None:
        I = as_first_fundamental_form(self.I)
        II = as_second_fundamental_form(self.II)
        if I.shape != (2, 2) or II.shape != (2, 2):
            raise ValueError(f"a surface map takes one (2, 2) I and II, got {I.shape} and {II.shape}")
        object.__setattr__(self, "I", 0.5 * (I + I.T))
        object.__setattr__(self, "II", 0.5 * (II + II.T))

    @property
    def stretch(self) -> np.ndarray:
        """``S = I^{1/2}`` (2×2 SPD)."""
        return _spd_sqrt(self.I)

    @property
    def bend(self) -> np.ndarray:
        """``II' = S⁻¹ II S⁻¹``: the bend in the stretched plane's coordinates (1/m)."""
        inv = np.linalg.inv(self.stretch)
        return inv @ self.II @ inv

    def evaluate(self, X: np.ndarray, height: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Points ``φ(X) + h n(X)`` ``(n, 3)`` (m), normals ``(n, 3)`` and surface frames
        ``R (n, 3, 3)`` (columns: the polar rotation of ∂φ, then n) at reference points
        ``X (n, 2)`` (m)."""
        X = np.asarray(X, dtype=np.float64).reshape(-1, 2)
        S = self.stretch
        Y = X @ S  # S symmetric: row-wise S X
        point, tangent = _bent_plane(self.bend, Y)
        gradient = tangent @ S  # ∂φ/∂X = ∂β/∂Y S, (n, 3, 2)
        frame = _surface_frame(gradient)
        normal = frame[:, :, 2]
        if height is not None:
            point = point + np.asarray(height, dtype=np.float64).reshape(-1, 1) * normal
        return point, normal, frame


def _bent_plane(bend: np.ndarray, Y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points ``(n, 3)`` and tangents ``∂β/∂Y (n, 3, 2)`` of the plane bent to second fundamental
    form ``bend`` at the origin: a circular cylinder if ``bend`` is singular, else a quadric."""
    n = Y.shape[0]
    point = np.zeros((n, 3))
    tangent = np.zeros((n, 3, 2))
    scale = float(np.abs(bend).max())
    if scale == 0.0:
        point[:, :2] = Y
        tangent[:, 0, 0] = tangent[:, 1, 1] = 1.0
        return point, tangent
    w, v = np.linalg.eigh(bend)
    if abs(w[0] * w[1]) <= DEVELOPABLE_TOLERANCE * scale**2:
        # Cylinder: curvature κ along u, straight along v = u turned by +90° (so u × v = e_z).
        k = int(np.argmax(np.abs(w)))
        kappa, u = float(w[k]), v[:, k]
        across = np.array([-u[1], u[0]])
        s, t = Y @ u, Y @ across
        u3, across3 = np.array([u[0], u[1], 0.0]), np.array([across[0], across[1], 0.0])
        angle = kappa * s
        point = (np.outer(t, across3) + np.outer(np.sin(angle) / kappa, u3)
                 + np.outer(2.0 * np.sin(0.5 * angle) ** 2 / kappa, [0.0, 0.0, 1.0]))
        along = np.outer(np.cos(angle), u3) + np.outer(np.sin(angle), [0.0, 0.0, 1.0])  # ∂β/∂s
        tangent = along[:, :, None] * u[None, None, :] + across3[None, :, None] * across[None, None, :]
        return point, tangent
    # Non-developable (saddle or dome): no surface carries this bend on a flat metric (Gauss). In
    # principal coordinates Z, the quadric (Z, ½ Σ κ_i Z_i²) strains the metric by κ_i² Z_i² along
    # each axis; the cubic terms below cancel that to second order and leave only the Gauss
    # defect, split evenly: g = diag(1 − K Z2²/2, 1 − K Z1²/2) + O(Z⁴), K = κ1 κ2.
    z = Y @ v
    k1, k2 = w
    gauss = k1 * k2
    z1, z2 = z[:, 0], z[:, 1]
    local = np.column_stack([
        z1 - k1**2 * z1**3 / 6.0 - 0.25 * gauss * z1 * z2**2,
        z2 - k2**2 * z2**3 / 6.0 - 0.25 * gauss * z1**2 * z2,
    ])
    point[:, :2] = local @ v.T
    point[:, 2] = 0.5 * (k1 * z1**2 + k2 * z2**2)
    d_local = np.empty((n, 2, 2))  # ∂(local)/∂Z
    d_local[:, 0, 0] = 1.0 - 0.5 * k1**2 * z1**2 - 0.25 * gauss * z2**2
    d_local[:, 0, 1] = d_local[:, 1, 0] = -0.5 * gauss * z1 * z2
    d_local[:, 1, 1] = 1.0 - 0.5 * k2**2 * z2**2 - 0.25 * gauss * z1**2
    tangent[:, :2, :] = v @ d_local @ v.T
    tangent[:, 2, :] = np.column_stack([k1 * z1, k2 * z2]) @ v.T
    return point, tangent


def _surface_frame(gradient: np.ndarray) -> np.ndarray:
    """``(n, 3, 3)`` frames: the rotation of the polar decomposition ``∂φ = R₂ U`` (two columns)
    and the unit normal ``r₁ × r₂``.

    ``R₂ = G C^(-1/2)`` with ``C = GᵀG`` (2×2 SPD for a surface map of full rank), in closed form:
    ``√C = (C + s Id)/t`` with ``s = √det C``, ``t = √(tr C + 2 s)`` (Cayley–Hamilton), inverted
    as a 2×2. It equals the SVD's ``U Vᵀ`` to round-off and costs a tenth of numpy's batched SVD
    over the tens of thousands of image points a curved tiling evaluates."""
    C = np.einsum("nki,nkj->nij", gradient, gradient)
    s = np.sqrt(C[:, 0, 0] * C[:, 1, 1] - C[:, 0, 1] * C[:, 1, 0])
    t = np.sqrt(C[:, 0, 0] + C[:, 1, 1] + 2.0 * s)
    root = C.copy()
    root[:, 0, 0] += s
    root[:, 1, 1] += s
    root /= t[:, None, None]
    det = root[:, 0, 0] * root[:, 1, 1] - root[:, 0, 1] * root[:, 1, 0]
    inverse = np.empty_like(root)
    inverse[:, 0, 0], inverse[:, 1, 1] = root[:, 1, 1] / det, root[:, 0, 0] / det
    inverse[:, 0, 1], inverse[:, 1, 0] = -root[:, 0, 1] / det, -root[:, 1, 0] / det
    r2 = gradient @ inverse
    normal = np.cross(r2[:, :, 0], r2[:, :, 1])
    return np.concatenate([r2, normal[:, :, None]], axis=2)


# -- the repeat on the surface ---------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class TiledRepeat:
    """A relaxed repeat placed on a sample's mid-surface, ready to solve.

    Attributes:
        surface: the mid-surface.
        model: the relaxed rest model on the curved tiling.
        state: the initial configuration (``ũ = 0``, frames turned with the surface).
        constraints: ``C_RVE`` (3 rows per yarn).
        reference: ``(N, 2)`` m, nodes' reference coordinates from the repeat's centre.
        height: ``(N,)`` m, nodes' heights above the mid-plane.
        area: ``p_x p_y`` (m²).
    """

    surface: SurfaceMap
    model: RodModel
    state: RodState
    constraints: LinearConstraints
    reference: np.ndarray
    height: np.ndarray
    area: float


def tile_repeat(relaxed: RelaxedRepeat, I, II) -> TiledRepeat:
    """Place ``relaxed`` on the mid-surface of ``(I, II)`` (see the module docstring)."""
    surface = SurfaceMap(np.asarray(I, dtype=np.float64), np.asarray(II, dtype=np.float64))
    flat = relaxed.model
    px, py = (float(v) for v in relaxed.repeat_size)
    rest = flat.node_rest_position
    reference = rest[:, :2] - np.array([0.5 * px, 0.5 * py])
    height = rest[:, 2] - rest[:, 2].mean()
    position, _, frame = surface.evaluate(reference, height)
    tiling = _curved_tiling(surface, flat, reference, height, position, frame, (px, py))
    lattice = surface.evaluate(np.array([[px, 0.0], [0.0, py], [0.0, 0.0]]))[0]
    model = retile(flat, tiling, lattice[:2] - lattice[2])
    quaternion = _turned_frames(model, relaxed.state.edge_quaternion, reference, (px, py), surface)
    state = RodState.from_model(model)
    state.node_position[:] = position
    state.edge_quaternion[:] = aligned_frames(model, position, quaternion)
    # C_RVE: per yarn and axis k, Σ_j (R_jᵀ x_j)_k keeps its initial value.
    return TiledRepeat(surface, model, state, yarn_centroid_constraints(model, frame), reference, height, px * py)


def _curved_tiling(surface, flat, reference, height, position, frame, repeat) -> CurvedTiling:
    """Per-node maps onto every tile the contacts can reach (with EXTRA_TILES to spare)."""
    # As find_pairs reaches: two radii, a margin of about one, and an edge.
    reach = 3.0 * float(flat.edge_radius.max()) + float(flat.edge_rest_length.max())
    # A compressed direction brings images closer: the same reach spans more tiles.
    smallest_stretch = math.sqrt(float(np.linalg.eigvalsh(surface.I).min()))
    needed = int(math.ceil(image_range(flat, flat.node_rest_position, reach).max() / smallest_stretch))
    extent = needed + EXTRA_TILES
    offsets = np.arange(-extent, extent + 1)
    images = np.array([(0, 0)] + [(i, j) for i in offsets for j in offsets if (i, j) != (0, 0)], dtype=np.int64)
    n, k = len(reference), len(images)
    shifted = (reference[:, None, :] + (images * np.asarray(repeat))[None, :, :]).reshape(-1, 2)
    image_position, _, image_frame = surface.evaluate(shifted, np.repeat(height, k))
    image_position = image_position.reshape(n, k, 3)
    image_frame = image_frame.reshape(n, k, 3, 3)
    # optimize=True: numpy's plain einsum loops over the N K tiny products ~20x slower.
    rotation = np.einsum("nkij,nlj->nkil", image_frame, frame, optimize=True)  # R(X + T) R(X)ᵀ
    translation = image_position - np.einsum("nkij,nj->nki", rotation, position, optimize=True)
    rotation[:, 0], translation[:, 0] = np.eye(3), 0.0  # the home tile exactly
    return CurvedTiling(images, np.ascontiguousarray(rotation), np.ascontiguousarray(translation))


def _turned_frames(model: RodModel, quaternion: np.ndarray, reference: np.ndarray, repeat, surface) -> np.ndarray:
    """Relaxed frames turned by the surface frame at each edge's reference midpoint."""
    start = reference[model.edge_nodes[:, 0]]
    end = reference[model.edge_nodes[:, 1]] + model.edge_tile * np.asarray(repeat)
    frame = surface.evaluate(0.5 * (start + end))[2]
    return rotate_frames(frame, quaternion)


def transfer_fluctuation(source: TiledRepeat, state: RodState, target: TiledRepeat) -> None:
    """Start ``target`` from ``state``, an equilibrium of ``source``: each node keeps its
    fluctuation ``ũ = x − φ(X) − h n`` in its surface frame (``ũ_target = R_t R_sᵀ ũ_source``, the
    corotated fluctuation C_RVE constrains), each frame turns with its first node's surface frame
    and is then aligned with its edge. Writes ``target.state``."""
    base_source, _, frame_source = source.surface.evaluate(source.reference, source.height)
    base_target, _, frame_target = target.surface.evaluate(target.reference, target.height)
    position, quaternion = _carry(base_source, frame_source, state, base_target, frame_target,
                                  target.model.edge_nodes[:, 0])
    target.state.node_position[:] = position
    target.state.edge_quaternion[:] = aligned_frames(target.model, position, quaternion)


def _carry(base_source: np.ndarray, frame_source: np.ndarray, state: RodState, base_target: np.ndarray,
           frame_target: np.ndarray, first_nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``state``'s nodes ``(N, 3)`` and frames ``(E, 4)`` carried from the surface points and frames
    ``base_source``, ``frame_source`` ``(N, 3)``, ``(N, 3, 3)`` to ``base_target``, ``frame_target``:
    each node's fluctuation turned by ``R_t R_sᵀ``, each frame by its first node's turn
    (``first_nodes`` ``(E,)``), not aligned with its edge."""
    turn = np.einsum("nij,nkj->nik", frame_target, frame_source)
    position = base_target + np.einsum("nij,nj->ni", turn, state.node_position - base_source)
    return position, rotate_frames(turn[first_nodes], state.edge_quaternion)


class CarriedEquilibrium:
    """An equilibrium ``state`` of ``tiled`` made ready to be carried to the surfaces of other first
    forms and the same second form, as :func:`transfer_fluctuation` carries it (each node's
    corotated fluctuation kept, frames turned with the surface and not re-aligned), for the energy
    there: :meth:`carried` gives the rods' model, the configuration and the contact ``pairs`` (a
    :class:`~yarnfit.engine.contact.ContactPairs` of ``tiled``) on the new surface. Only the maps
    onto the periodic images that the ghost edges, the joints and the pairs use are evaluated (a
    full tiling's maps reach every tile a contact search may need: ~10 times the points)."""

    def __init__(self, relaxed: RelaxedRepeat, tiled: TiledRepeat, state: RodState, pairs) -> None:
        self.tiled, self.pairs = tiled, pairs
        self.repeat = np.asarray(relaxed.repeat_size, dtype=np.float64)
        self.base, _, self.frame = tiled.surface.evaluate(tiled.reference, tiled.height)
        self.state = state
        model = tiled.model
        b = pairs.pairs[:, 1]
        joint = model.joint_edges[:, 0]
        # Every (node, tile) whose map is used: ghost-edge ends, joints, and the pairs' second edges.
        node = np.concatenate([model.edge_nodes[:, 1], model.edge_nodes[joint, 1], model.edge_nodes[b, 0],
                               model.edge_nodes[b, 1]])
        tile = np.concatenate([model.edge_tile, model.edge_tile[joint], pairs.images, pairs.images + model.edge_tile[b]])
        keys, self.index = np.unique(np.column_stack([node, tile]), axis=0, return_inverse=True)
        self.index = self.index.reshape(-1)
        self.node, self.tile = keys[:, 0], keys[:, 1:]
        self.sizes = np.cumsum([0, model.n_edges, len(joint), len(b), len(b)])

    def carried(self, I: np.ndarray) -> tuple[RodModel, np.ndarray, np.ndarray, object]:
        """``(model, position (N, 3), quaternion (E, 4), pairs)`` on the surface of first form ``I``
        ``(2, 2)`` and the tiling's second form."""
        tiled, model = self.tiled, self.tiled.model
        surface = SurfaceMap(np.asarray(I, dtype=np.float64), tiled.surface.II)
        base, _, frame = surface.evaluate(tiled.reference, tiled.height)
        position, quaternion = _carry(self.base, self.frame, self.state, base, frame, model.edge_nodes[:, 0])
        # The maps R(X + T) R(X)ᵀ, x ↦ Q x + c with c taking the node's base point to its image's
        # (as _curved_tiling), the home tile exactly the identity.
        shifted = tiled.reference[self.node] + self.tile * self.repeat
        image, _, image_frame = surface.evaluate(shifted, tiled.height[self.node])
        rotation = np.einsum("kij,klj->kil", image_frame, frame[self.node])
        translation = image - np.einsum("kij,kj->ki", rotation, base[self.node])
        home = np.all(self.tile == 0, axis=1)
        rotation[home], translation[home] = np.eye(3), 0.0
        rotation, translation = rotation[self.index], translation[self.index]
        edges, joints, first, second = (slice(self.sizes[k], self.sizes[k + 1]) for k in range(4))
        moved = replace(model, edge_end_rotation=np.ascontiguousarray(rotation[edges]),
                        edge_offset=np.ascontiguousarray(translation[edges]),
                        joint_frame_rotation=as_frames(Rotation.from_matrix(rotation[joints])))
        pairs = self.pairs
        a = pairs.pairs[:, 0]
        pair_rotation = np.empty((len(pairs), 4, 3, 3))
        pair_translation = np.empty((len(pairs), 4, 3))
        pair_rotation[:, 0], pair_translation[:, 0] = np.eye(3), 0.0
        pair_rotation[:, 1], pair_translation[:, 1] = moved.edge_end_rotation[a], moved.edge_offset[a]
        pair_rotation[:, 2], pair_translation[:, 2] = rotation[first], translation[first]
        pair_rotation[:, 3], pair_translation[:, 3] = rotation[second], translation[second]
        return moved, position, quaternion, ContactPairs(pairs.pairs, pairs.images, pair_rotation, pair_translation)
