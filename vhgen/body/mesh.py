"""The MakeHuman base mesh and its rig, read from MPFB2 assets.

Frame: Y up, the subject faces +Z and has their own left at +X (the same frame as CMU
BVH files), metres, feet on the floor (y = 0 at the lowest body vertex of the base mesh).
The OBJ is in decimetres; MPFB2's rig JSON is in Blender's Z-up frame, used only for bone
topology, roll and the cube names: joint positions come from the joint-cube vertex groups
of the (shaped) mesh, so they follow shape changes.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vhgen.errors import AssetError

OBJ_TO_METRES = 0.1


@dataclass(frozen=True, eq=False)
class BaseMesh:
    """All vertices of base.obj and the triangles of selected groups.

    vertices : (V, 3) float64 metres (all 19,158 vertices, joint cubes included), feet on
        the floor.
    vertices_obj : (V, 3) float64 as in the OBJ (decimetres, not grounded): what shape
        targets offset.
    faces : (T, 3) int64 triangles (quads split along their 0-2 diagonal).
    face_group : (T,) int64 index into ``groups`` of the OBJ group each triangle came from.
    groups : OBJ group names in file order.
    vertex_groups : MPFB2 vertex groups, name -> (n,) int64 vertex indices.
    floor_offset : metres subtracted from y so the body's lowest vertex is at 0.
    """

    vertices: np.ndarray
    vertices_obj: np.ndarray
    faces: np.ndarray
    face_group: np.ndarray
    groups: list[str]
    vertex_groups: dict[str, np.ndarray]
    floor_offset: float


def read_obj(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """Minimal OBJ reader keeping vertex order and groups: (V,3) verts, (T,3) tris, group ids."""
    verts: list[str] = []
    tris: list[tuple[int, int, int]] = []
    tri_group: list[int] = []
    groups: list[str] = []
    g = -1
    try:
        fh = open(path, encoding="utf-8")
    except OSError as e:
        raise AssetError(f"cannot read {path}: {e.strerror}") from None
    with fh:
        for lineno, line in enumerate(fh, 1):
            if line.startswith("v "):
                verts.append(line[2:])
            elif line.startswith("f "):
                idx = [int(tok.split("/", 1)[0]) - 1 for tok in line.split()[1:]]
                if len(idx) < 3:
                    raise AssetError(f"{path}:{lineno}: face with {len(idx)} vertices")
                for k in range(1, len(idx) - 1):
                    tris.append((idx[0], idx[k], idx[k + 1]))
                    tri_group.append(g)
            elif line.startswith("g "):
                groups.append(line[2:].strip())
                g = len(groups) - 1
    v = np.array(" ".join(verts).split(), dtype=np.float64).reshape(-1, 3)
    return v, np.asarray(tris, dtype=np.int64), np.asarray(tri_group, dtype=np.int64), groups


def load_base_mesh(asset_dir: Path) -> BaseMesh:
    """Read base.obj and the vertex groups; convert to metres with the feet on y = 0."""
    verts, faces, face_group, groups = read_obj(asset_dir / "3dobjs" / "base.obj")
    with open(asset_dir / "mesh_metadata" / "basemesh_vertex_groups.json") as f:
        raw_groups = json.load(f)
    vgroups = {}
    for name, ranges in raw_groups.items():
        idx = np.concatenate([np.arange(a, b + 1) for a, b in ranges]) if ranges else \
            np.zeros(0, np.int64)
        vgroups[name] = idx.astype(np.int64)
    raw = verts
    verts, floor = to_metres_grounded(raw, faces[face_group == groups.index("body")])
    for a in (raw, verts, faces, face_group):
        a.setflags(write=False)
    return BaseMesh(verts, raw, faces, face_group, groups, vgroups, floor)


def to_metres_grounded(vertices_obj: np.ndarray, body_faces: np.ndarray) -> tuple[np.ndarray,
                                                                                   float]:
    """OBJ decimetres -> metres with the lowest body vertex on y = 0; returns the shift."""
    verts = np.asarray(vertices_obj, np.float64) * OBJ_TO_METRES
    floor = float(verts[np.unique(body_faces), 1].min())
    verts[:, 1] -= floor
    return verts, floor


@dataclass(frozen=True, eq=False)
class Rig:
    """A skeleton fitted to a mesh.

    names : bone names, parents before children.
    parents : (B,) int64, -1 for the root.
    heads, tails : (B, 3) float64 rest positions in the mesh frame (metres).
    rolls : (B,) float64 Blender roll (radians), kept for later roll-aware retargeting.
    """

    names: list[str]
    parents: np.ndarray
    heads: np.ndarray
    tails: np.ndarray
    rolls: np.ndarray

    def index(self, name: str) -> int:
        return self.names.index(name)


def _joint_position(spec: dict, vertices: np.ndarray, vgroups: dict[str, np.ndarray],
                    where: str) -> np.ndarray:
    strategy = spec.get("strategy")
    if strategy == "CUBE":
        cube = spec["cube_name"]
        if cube not in vgroups:
            raise AssetError(f"{where}: joint cube {cube!r} is not a vertex group of the mesh")
        return vertices[vgroups[cube]].mean(axis=0)
    if strategy == "MEAN":
        return vertices[np.asarray(spec["vertex_indices"], np.int64)].mean(axis=0)
    if strategy == "VERTEX":
        return vertices[int(spec["vertex_index"])].copy()
    raise AssetError(f"{where}: unknown joint strategy {strategy!r}")


def load_rig(asset_dir: Path, vertices: np.ndarray, vgroups: dict[str, np.ndarray],
             rig_name: str = "cmu_mb") -> Rig:
    """Fit MPFB2's ``rig.<rig_name>.json`` to ``vertices`` (joint positions from the cubes)."""
    path = asset_dir / "rigs" / "standard" / f"rig.{rig_name}.json"
    try:
        with open(path) as f:
            spec = json.load(f)
    except OSError as e:
        raise AssetError(f"cannot read rig {path}: {e.strerror}") from None
    # order parents before children
    names: list[str] = []
    pending = dict(spec)
    while pending:
        progressed = False
        for name in sorted(pending):
            parent = pending[name].get("parent") or ""
            if parent == "" or parent in names:
                names.append(name)
                del pending[name]
                progressed = True
        if not progressed:
            raise AssetError(f"{path}: bones with missing or cyclic parents: {sorted(pending)}")
    parents = np.array([names.index(spec[n]["parent"]) if spec[n].get("parent") else -1
                        for n in names], dtype=np.int64)
    heads = np.array([_joint_position(spec[n]["head"], vertices, vgroups, f"{path}:{n}.head")
                      for n in names])
    tails = np.array([_joint_position(spec[n]["tail"], vertices, vgroups, f"{path}:{n}.tail")
                      for n in names])
    rolls = np.array([float(spec[n].get("roll", 0.0)) for n in names])
    for a in (parents, heads, tails, rolls):
        a.setflags(write=False)
    return Rig(names, parents, heads, tails, rolls)


def load_weights(asset_dir: Path, rig: Rig, num_vertices: int,
                 rig_name: str = "cmu_mb") -> np.ndarray:
    """Dense skinning weights (V, B) float64 from MPFB2's ``weights.<rig_name>.json``."""
    path = asset_dir / "rigs" / "standard" / f"weights.{rig_name}.json"
    with open(path) as f:
        data = json.load(f)["weights"]
    dense = np.zeros((num_vertices, len(rig.names)), dtype=np.float64)
    for bone, pairs in data.items():
        if bone not in rig.names:
            raise AssetError(f"{path}: weights for bone {bone!r} which the rig lacks")
        if not pairs:
            continue
        arr = np.asarray(pairs, dtype=np.float64)
        dense[arr[:, 0].astype(np.int64), rig.index(bone)] += arr[:, 1]
    return dense


def truncate_weights(dense: np.ndarray, k: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """Keep the ``k`` largest weights per vertex and renormalise them to sum 1.

    dense : (V, B) non-negative.  Returns indices (V, k) int32 and weights (V, k) float64.
    Ties keep the lower bone index. A vertex whose kept weights sum to zero (no influence
    at all) is bound rigidly to bone 0 (the root) with weight 1, so it follows the body
    instead of collapsing to the origin.
    """
    dense = np.asarray(dense, dtype=np.float64)
    k_eff = min(k, dense.shape[1])
    order = np.argsort(-dense, axis=1, kind="stable")[:, :k_eff]
    w = np.take_along_axis(dense, order, axis=1)
    if k_eff < k:
        order = np.pad(order, ((0, 0), (0, k - k_eff)))
        w = np.pad(w, ((0, 0), (0, k - k_eff)))
    s = w.sum(axis=1, keepdims=True)
    empty = s[:, 0] <= 0
    w = np.where(empty[:, None], 0.0, w / np.where(s > 0, s, 1.0))
    order[empty] = 0
    w[empty, 0] = 1.0
    return order.astype(np.int32), w
