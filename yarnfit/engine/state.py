"""Rod states and loads: plain arrays that solvers read and update."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .model import RodModel, check_positions, check_quaternions


@dataclass
class RodState:
    """Configuration and velocities of a :class:`RodModel`.

    Attributes:
        node_position: ``(N, 3)`` m.
        edge_quaternion: ``(E, 4)`` unit quaternions (w, x, y, z), body to world.
        node_velocity: ``(N, 3)`` m/s.
        edge_angular_velocity: ``(E, 3)`` rad/s, world frame.
    """

    node_position: np.ndarray
    edge_quaternion: np.ndarray
    node_velocity: np.ndarray
    edge_angular_velocity: np.ndarray

    @classmethod
    def from_model(cls, model: RodModel) -> "RodState":
        """The model's initial configuration, at rest."""
        return cls(
            node_position=np.array(model.node_rest_position, dtype=np.float64),
            edge_quaternion=np.array(model.edge_rest_quaternion, dtype=np.float64),
            node_velocity=np.zeros((model.n_nodes, 3)),
            edge_angular_velocity=np.zeros((model.n_edges, 3)),
        )

    def copy(self) -> "RodState":
        return RodState(
            self.node_position.copy(),
            self.edge_quaternion.copy(),
            self.node_velocity.copy(),
            self.edge_angular_velocity.copy(),
        )

    def check(self, model: RodModel) -> None:
        """Raise ``ValueError`` unless shapes match ``model`` and every value is finite, with
        unit quaternions."""
        check_positions(self.node_position, model.n_nodes, "node_position")
        check_quaternions(self.edge_quaternion, "edge_quaternion")
        if self.edge_quaternion.shape[0] != model.n_edges:
            raise ValueError(
                f"edge_quaternion must have shape ({model.n_edges}, 4), got {self.edge_quaternion.shape}"
            )
        check_positions(self.node_velocity, model.n_nodes, "node_velocity")
        check_positions(self.edge_angular_velocity, model.n_edges, "edge_angular_velocity")


@dataclass
class Loads:
    """External loads on a :class:`RodModel`.

    Attributes:
        gravity: ``(3,)`` m/s², acting on the lumped node masses.
        node_force: ``(N, 3)`` N, dead loads on nodes.
        edge_moment: ``(E, 3)`` N·m, dead moments (fixed world axes) on edge frames.
    """

    gravity: np.ndarray
    node_force: np.ndarray
    edge_moment: np.ndarray

    @classmethod
    def zeros(cls, model: RodModel, gravity=(0.0, 0.0, 0.0)) -> "Loads":
        return cls(
            gravity=np.array(gravity, dtype=np.float64),
            node_force=np.zeros((model.n_nodes, 3)),
            edge_moment=np.zeros((model.n_edges, 3)),
        )

    def check(self, model: RodModel) -> None:
        """Raise ``ValueError`` unless shapes match ``model`` and every value is finite."""
        g = np.asarray(self.gravity)
        if g.shape != (3,) or not np.all(np.isfinite(g)):
            raise ValueError(f"gravity must be a finite 3-vector, got {self.gravity!r}")
        check_positions(self.node_force, model.n_nodes, "node_force")
        check_positions(self.edge_moment, model.n_edges, "edge_moment")

    def total_node_force(self, model: RodModel) -> np.ndarray:
        """Dead load on each node including its weight, ``(N, 3)`` N."""
        return self.node_force + model.node_mass[:, None] * np.asarray(self.gravity)[None, :]

    def scaled(self, factor: float) -> "Loads":
        """These loads times ``factor`` (for load stepping)."""
        return Loads(self.gravity * factor, self.node_force * factor, self.edge_moment * factor)
