"""Geometry below the body and the scene (pure NumPy): the mesh primitives every mesh
builder shares (:mod:`vhgen.geom.primitives`) and the plane finder with the sensor's
depth-noise model (:mod:`vhgen.geom.planes`)."""
