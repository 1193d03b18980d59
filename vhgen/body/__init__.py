"""The MakeHuman body: base mesh, fitted rig, skinning weights, body-part labels."""

from vhgen.body.avatar import Body, build_body
from vhgen.body.labels import LabelScheme
from vhgen.body.mesh import Rig
from vhgen.body.skinning import bone_matrices, posed_heads, skin_vertices

__all__ = ["Body", "LabelScheme", "Rig", "bone_matrices", "build_body", "posed_heads",
           "skin_vertices"]
