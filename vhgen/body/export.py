"""Export a shaped, posed avatar with label colours (OBJ, PLY, GLB) through trimesh."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from vhgen.body.avatar import Body
from vhgen.body.skinning import bone_matrices, skin_vertices, skin_vertices_dqs


def posed_mesh(body: Body, rotations: np.ndarray | None = None, root: np.ndarray | None = None,
               skinning: str = "lbs"):
    """A trimesh.Trimesh of ``body`` in a pose (rest if None), faces coloured by label
    (carried things that are not the person grey). A dressed body with ``lbs`` is posed
    as the renderer draws it (hands pressing garments, legs pushing skirts:
    :func:`vhgen.body.contact.dressed_positions`)."""
    import trimesh

    b = body.num_bones
    if rotations is None:
        rotations = np.broadcast_to(np.eye(3), (b, 3, 3))
    if root is None:
        root = body.rig.heads[int(np.flatnonzero(body.rig.parents < 0)[0])]
    mats = bone_matrices(body.rig, rotations, root)
    if body.offsets is not None and body.press is not None and skinning == "lbs":
        from vhgen.body.contact import body_contacts, dressed_positions

        contacts = body_contacts(body.rig, body.vertices - body.offsets, body.joints)
        verts = dressed_positions(body.vertices, body.offsets, body.press, body.joints,
                                  body.weights, mats, contacts)
    else:
        skin = skin_vertices_dqs if skinning == "dqs" else skin_vertices
        verts = skin(body.vertices, body.joints, body.weights, mats)
    rgb = body.scheme.palette[body.face_labels]
    if body.face_classes is not None:
        rgb[body.face_classes > 0] = (128, 128, 128)
    colors = np.column_stack([rgb, np.full(len(body.faces), 255, np.uint8)])
    mesh = trimesh.Trimesh(verts, body.faces, face_colors=colors, process=False)
    mesh.metadata["label_names"] = body.scheme.names
    return mesh


def export_mesh(mesh, path: str | Path) -> Path:
    """Write .obj, .ply or .glb (chosen by suffix)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    mesh.export(path)
    return path
