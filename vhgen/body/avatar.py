"""A renderable body: the MakeHuman base mesh without helper geometry, fitted rig,
fixed-length skinning weights and per-triangle part labels."""

from __future__ import annotations

import functools
import hashlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from vhgen.body.chart import BodyChart, build_chart
from vhgen.body.labels import LabelScheme
from vhgen.body.mesh import (
    BaseMesh,
    Rig,
    load_base_mesh,
    load_rig,
    load_weights,
    to_metres_grounded,
    truncate_weights,
)
from vhgen.body.shape import MacroTargets, Shape
from vhgen.body.wardrobe import Outfit
from vhgen.errors import AssetError, ConfigError

BODY_GROUP = "body"
HAIR_GUIDE = "helper-hair"  # MakeHuman's long-hair helper: how wide long hair falls
CLOTHING_GROUPS = {"tights": "helper-tights", "skirt": "helper-skirt"}


@dataclass(frozen=True, eq=False)
class Body:
    """vertices (V,3) float64 metres; faces (T,3) int64; joints/weights (V,K); face_labels (T,).

    A dressed body (:mod:`vhgen.body.outfit`) also has ``offsets`` (V, 3): how far each
    vertex lies out from the skin under it (a garment's thickness; the skin is
    ``vertices - offsets``), ``press`` (V,) uint8: which of its own hands may press the
    garment there towards the skin (:func:`vhgen.body.garments.press_mask`), and
    ``face_classes`` (T,) uint8: a triangle's scene class when it is not the person's
    (carried things; 0 = the person's). All three are None on a bare body. The outfit's
    own parts are the last ``appended_faces`` triangles (on vertices of their own).
    """

    vertices: np.ndarray
    faces: np.ndarray
    joints: np.ndarray
    weights: np.ndarray
    face_labels: np.ndarray
    rig: Rig
    scheme: LabelScheme
    params: dict  # what it was built from as plain data: the manifest's avatar_params
    offsets: np.ndarray | None = None
    press: np.ndarray | None = None
    face_classes: np.ndarray | None = None
    appended_faces: int = 0

    @property
    def num_bones(self) -> int:
        return len(self.rig.names)

    @property
    def hip_drop(self) -> float:
        """Height of the root bone's head above the lowest bone end, rest pose (metres)."""
        root = int(np.flatnonzero(self.rig.parents < 0)[0])
        low = min(self.rig.heads[:, 1].min(), self.rig.tails[:, 1].min())
        return float(self.rig.heads[root, 1] - low)

    def fingerprint(self) -> str:
        """sha1 of the arrays, to tell two bodies apart in a manifest."""
        h = hashlib.sha1()
        for a in (self.vertices, self.faces, self.joints, self.weights, self.face_labels,
                  self.offsets, self.press, self.face_classes):
            if a is not None:
                h.update(np.ascontiguousarray(a).tobytes())
        return h.hexdigest()[:16]


@functools.lru_cache(maxsize=4)
def _base(asset_dir: Path) -> BaseMesh:
    return load_base_mesh(asset_dir)


@functools.lru_cache(maxsize=4)
def _targets(asset_dir: Path) -> MacroTargets:
    return MacroTargets(asset_dir)


def _faces(base: BaseMesh, clothing: tuple[str, ...]) -> np.ndarray:
    for c in clothing:
        if c not in CLOTHING_GROUPS:
            raise ConfigError(None, "clothing", f"unknown helper {c!r} (one of "
                                                f"{', '.join(CLOTHING_GROUPS)})")
    groups = [BODY_GROUP] + [CLOTHING_GROUPS[c] for c in clothing]
    ids = [base.groups.index(g) for g in groups]
    return base.faces[np.isin(base.face_group, ids)]


@functools.lru_cache(maxsize=16)
def _topology(asset_dir: Path, clothing: tuple[str, ...], rig_name: str, max_influences: int
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """What every avatar with this clothing shares, whatever its shape: the base vertices
    kept (V,), the triangles re-indexed to them (T, 3), and the truncated skinning
    (joints, weights) (V, k). Read-only; parsed once per process (the weights JSON alone
    took 25 ms per body)."""
    base = _base(asset_dir)
    faces_all = _faces(base, clothing)
    keep = np.unique(faces_all)
    remap = np.full(len(base.vertices), -1, dtype=np.int64)
    remap[keep] = np.arange(len(keep))
    faces = remap[faces_all]
    # the weights name bones; the rig here only orders them (the same for every shape)
    rig = load_rig(asset_dir, base.vertices, base.vertex_groups, rig_name)
    dense = load_weights(asset_dir, rig, len(base.vertices), rig_name)
    joints, weights = truncate_weights(dense[keep], max_influences)
    for a in (keep, faces, joints, weights):
        a.setflags(write=False)
    return keep, faces, joints, weights


@functools.lru_cache(maxsize=16)
def _labels(asset_dir: Path, scheme: LabelScheme, clothing: tuple[str, ...],
            rig_name: str) -> np.ndarray:
    """Per-triangle labels, decided once on the unshaped base mesh so that every avatar
    has the same part boundaries (the topology is shared)."""
    base = _base(asset_dir)
    rig = load_rig(asset_dir, base.vertices, base.vertex_groups, rig_name)
    dense = load_weights(asset_dir, rig, len(base.vertices), rig_name)
    labels = scheme.assign(rig, base.vertices, _faces(base, clothing), dense,
                           base.vertex_groups)
    labels.setflags(write=False)
    return labels


@functools.lru_cache(maxsize=4)
def _chart(asset_dir: Path, rig_name: str) -> BodyChart:
    """The garment chart of the body mesh (its body vertices and triangles come first in
    every topology), on the unshaped base mesh: once per process."""
    base = _base(asset_dir)
    faces = base.faces[base.face_group == base.groups.index(BODY_GROUP)]
    nv = int(faces.max()) + 1
    if np.unique(faces).size != nv:
        raise AssetError("base.obj: the body's vertices are not the first of the mesh")
    rig = load_rig(asset_dir, base.vertices, base.vertex_groups, rig_name)
    dense = load_weights(asset_dir, rig, len(base.vertices), rig_name)
    return build_chart(rig, base.vertices[:nv], faces, dense[:nv])


def build_body(asset_dir: Path, scheme: LabelScheme, *, shape: Shape | None = None,
               scale: float = 1.0, clothing: tuple[str, ...] = (), rig_name: str = "cmu_mb",
               max_influences: int = 4, outfit: Outfit | None = None) -> Body:
    """Assemble a body from MPFB2 assets.

    shape : MakeHuman macro modifiers (None: the unmodified base mesh).
    scale : uniform scale about the point between the feet, after the shape.
    clothing : optional helper geometry to include and label ("tights", "skirt").
    outfit : garments, hair, shoes and carried things (:mod:`vhgen.body.wardrobe` draws
        them, ``avatar_params["outfit"]`` records them as plain data); None: a bare body.
    ``params`` of the body records all of these as plain data (the manifest's
    ``avatar_params``, from which :meth:`AvatarParams.from_dict` rebuilds them).
    Joint positions come from the joint cubes of the shaped mesh, so the rig fits it.
    """
    asset_dir = Path(asset_dir)
    base = _base(asset_dir)
    clothing = tuple(clothing)
    raw = base.vertices_obj
    if shape is not None:
        raw = raw + _targets(asset_dir).offsets(shape, len(raw))
    verts_all, _ = to_metres_grounded(raw, base.faces[base.face_group ==
                                                      base.groups.index(BODY_GROUP)])
    verts_all *= float(scale)
    rig = load_rig(asset_dir, verts_all, base.vertex_groups, rig_name)
    keep, faces, joints, weights = _topology(asset_dir, clothing, rig_name, max_influences)
    verts = verts_all[keep]
    verts.setflags(write=False)
    labels = _labels(asset_dir, scheme, clothing, rig_name)
    params = {"scale": float(scale), "rig": rig_name, "max_influences": int(max_influences),
              "clothing": list(clothing)}
    if shape is not None:
        params["shape"] = shape.to_dict()
    if outfit is None:
        return Body(vertices=verts, faces=faces, joints=joints, weights=weights,
                    face_labels=labels, rig=rig, scheme=scheme, params=params)
    from vhgen.body.outfit import dress_arrays, make_fit

    chart = _chart(asset_dir, rig_name)
    fit = make_fit(verts, faces[:len(chart.face_region)], joints, weights, rig, chart)
    guide = verts_all[base.vertex_groups[HAIR_GUIDE]]
    d = dress_arrays(verts, faces, joints, weights, labels, fit, outfit, guide)
    for a in d.values():
        a.setflags(write=False)
    params["outfit"] = outfit.to_dict()
    return Body(vertices=d["vertices"], faces=d["faces"], joints=d["joints"],
                weights=d["weights"], face_labels=d["face_labels"], rig=rig, scheme=scheme,
                params=params, offsets=d["offsets"], press=d["press"],
                face_classes=d["face_classes"], appended_faces=len(d["faces"]) - len(faces))


@dataclass(frozen=True)
class AvatarParams:
    """What one avatar of a job's plan is built from (``Plan.avatars[i]``): its macro
    ``shape``, uniform ``scale``, helper ``clothing`` ("tights", "skirt") and its
    ``outfit`` when the job dresses its avatars. Plain data only in the manifest
    (:meth:`to_dict`)."""

    shape: Shape
    scale: float
    clothing: tuple[str, ...] = ()
    outfit: Outfit | None = None

    def to_dict(self) -> dict[str, Any]:
        """``shape`` (:meth:`Shape.to_dict`), ``scale``, ``clothing`` (a list) and, when
        dressed, ``outfit`` (:meth:`Outfit.to_dict`)."""
        d: dict[str, Any] = {"shape": self.shape.to_dict(), "scale": self.scale,
                             "clothing": list(self.clothing)}
        if self.outfit is not None:
            d["outfit"] = self.outfit.to_dict()
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> AvatarParams:
        """Rebuild from :meth:`to_dict` output or a manifest's ``avatar_params`` (its
        other keys ignored; an empty or absent ``outfit`` is none)."""
        outfit = d.get("outfit")
        return cls(Shape.from_dict(d["shape"]), float(d["scale"]), tuple(d["clothing"]),
                   Outfit.from_dict(outfit) if outfit else None)


def build_avatar(asset_dir: str | Path, scheme: LabelScheme, avatar: AvatarParams) -> Body:
    """The shaped body of one avatar of a job's plan: the one recipe the driver and the
    workers share."""
    return build_body(Path(asset_dir), scheme, shape=avatar.shape, scale=avatar.scale,
                      clothing=avatar.clothing, outfit=avatar.outfit)
