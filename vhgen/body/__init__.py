"""The MakeHuman body: base mesh, fitted rig, skinning weights, body-part labels."""

from vhgen.body.avatar import AvatarParams, Body, build_body
from vhgen.body.labels import LabelScheme
from vhgen.body.mesh import Rig
from vhgen.body.skinning import bone_matrices, posed_heads, skin_vertices
from vhgen.body.wardrobe import Outfit

__all__ = ["AvatarParams", "Body", "LabelScheme", "Outfit", "Rig", "bone_matrices",
           "build_body", "posed_heads", "skin_vertices"]
