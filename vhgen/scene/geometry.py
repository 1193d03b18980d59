"""Static scene geometry as plain triangle meshes with a scene class per triangle.

World frame: y up, the floor is the plane y = 0 (poses are grounded so feet touch it),
metres. Meshes are float64 here; the renderer rounds them to float32 once.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# Scene classes (the ``classes`` array): ids are positions in this tuple. A scene config
# appends its props' own classes (``SceneConfig.class_names``); these first five keep
# their ids in every store.
SCENE_CLASSES: tuple[str, ...] = ("background", "floor", "wall", "prop", "person")
BACKGROUND, FLOOR, WALL, PROP, PERSON = range(5)
MAX_SCENE_CLASSES = 256  # the classes array is uint8


def pack_ids(labels: np.ndarray, instances: np.ndarray, classes: np.ndarray) -> np.ndarray:
    """(H, W) uint32: part label | instance << 8 | class << 16, the one id image the
    renderer writes and the sensor moves with the pixels (so the three stay aligned)."""
    return (labels.astype(np.uint32) | (instances.astype(np.uint32) << 8)
            | (classes.astype(np.uint32) << 16))


def id_bytes(packed: np.ndarray) -> np.ndarray:
    """(..., 4) uint8 view of packed ids (no copy): [..., 0] labels, [..., 1] instances,
    [..., 2] classes."""
    p = np.asarray(packed).astype("<u4", copy=False)
    return p.view(np.uint8).reshape(p.shape + (4,))


def unpack_ids(packed: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The inverse of :func:`pack_ids`: labels, instances, classes, (H, W) uint8 each."""
    b = id_bytes(packed)
    return (np.ascontiguousarray(b[..., 0]), np.ascontiguousarray(b[..., 1]),
            np.ascontiguousarray(b[..., 2]))


@dataclass(frozen=True, eq=False)
class StaticMesh:
    """A rigid mesh in world coordinates: vertices (V, 3) float64 metres, faces (T, 3)
    int64, face_classes (T,) uint8 scene class per triangle."""

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    face_classes: np.ndarray


def quad(corners: np.ndarray, cls: int, name: str) -> StaticMesh:
    """Two triangles over 4 corners (4, 3) given in order around the quad."""
    return StaticMesh(name, np.asarray(corners, np.float64), np.array([[0, 1, 2], [0, 2, 3]]),
                      np.full(2, cls, np.uint8))


def floor_mesh(x: tuple[float, float], z: tuple[float, float]) -> StaticMesh:
    """The floor rectangle [x0, x1] x [z0, z1] at y = 0."""
    (x0, x1), (z0, z1) = x, z
    return quad(np.array([[x0, 0, z0], [x1, 0, z0], [x1, 0, z1], [x0, 0, z1]]), FLOOR, "floor")


def room_walls(corners_xz: np.ndarray, height: float) -> StaticMesh:
    """The 4 walls of a room whose floor has corners (4, 2) (x, z) in order, from the floor
    up to ``height`` metres, one mesh of 8 triangles, class wall."""
    c = np.asarray(corners_xz, np.float64)
    verts, faces = [], []
    for k in range(4):
        a, b = c[k], c[(k + 1) % 4]
        base = 4 * k
        verts += [[a[0], 0.0, a[1]], [b[0], 0.0, b[1]], [b[0], height, b[1]],
                  [a[0], height, a[1]]]
        faces += [[base, base + 1, base + 2], [base, base + 2, base + 3]]
    return StaticMesh("walls", np.array(verts), np.array(faces), np.full(8, WALL, np.uint8))


def room_floor(corners_xz: np.ndarray) -> StaticMesh:
    """The floor polygon of a room (4 corners (x, z) in order) at y = 0."""
    c = np.asarray(corners_xz, np.float64)
    return quad(np.column_stack([c[:, 0], np.zeros(4), c[:, 1]]), FLOOR, "floor")
