"""A renderable body: the MakeHuman base mesh without helper geometry, fitted rig,
fixed-length skinning weights and per-triangle part labels."""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vhgen.body.labels import LabelScheme
from vhgen.body.mesh import Rig, load_base_mesh, load_rig, load_weights, truncate_weights

BODY_GROUP = "body"


@dataclass(frozen=True, eq=False)
class Body:
    """vertices (V,3) float64 metres; faces (T,3) int64; joints/weights (V,K); face_labels (T,)."""

    vertices: np.ndarray
    faces: np.ndarray
    joints: np.ndarray
    weights: np.ndarray
    face_labels: np.ndarray
    rig: Rig
    scheme: LabelScheme
    params: dict

    @property
    def num_bones(self) -> int:
        return len(self.rig.names)

    def fingerprint(self) -> str:
        """sha1 of the arrays, to tell two bodies apart in a manifest."""
        h = hashlib.sha1()
        for a in (self.vertices, self.faces, self.joints, self.weights, self.face_labels):
            h.update(np.ascontiguousarray(a).tobytes())
        return h.hexdigest()[:16]


def build_body(asset_dir: Path, scheme: LabelScheme, *, rig_name: str = "cmu_mb",
               max_influences: int = 4, scale: float = 1.0) -> Body:
    """Assemble the body from MPFB2 assets.

    ``scale`` scales the whole body uniformly about the point between the feet (a first
    avatar parameter; shape modifiers come with the human-model work). Joint positions are
    taken from the joint cubes of the scaled mesh, so the rig fits the body.
    """
    base = load_base_mesh(asset_dir)
    verts_all = base.vertices * float(scale)
    rig = load_rig(asset_dir, verts_all, base.vertex_groups, rig_name)
    dense_all = load_weights(asset_dir, rig, len(verts_all), rig_name)
    faces_all = base.faces[base.face_group == base.groups.index(BODY_GROUP)]
    keep = np.unique(faces_all)
    remap = np.full(len(verts_all), -1, dtype=np.int64)
    remap[keep] = np.arange(len(keep))
    faces = remap[faces_all]
    verts = verts_all[keep]
    dense = dense_all[keep]
    labels = scheme.assign(rig, verts, faces, dense)
    joints, weights = truncate_weights(dense, max_influences)
    for a in (verts, faces, joints, weights, labels):
        a.setflags(write=False)
    return Body(vertices=verts, faces=faces, joints=joints, weights=weights,
                face_labels=labels, rig=rig, scheme=scheme,
                params={"scale": float(scale), "rig": rig_name,
                        "max_influences": int(max_influences)})
