"""Procedural clutter: what makes a room look lived in (pure).

Shelves and bookcases full of books and things, plants (trunk, branches, leaves), stairs,
TVs on stands, desks with a monitor and an office chair, floor lamps, radiators, windows
(glass gives no return), curtains, doors open at an angle onto a corridor, boxes, bags,
objects on the floor and on every surface, pictures and shelves on the walls, chairs
standing free and coat stands hung with coats (person-sized, not people).

* :mod:`~vhgen.scene.clutter.kinds`: one record per kind (its sizes, builder, how it
  stands, ...) in one registry, :data:`KINDS`;
* :mod:`~vhgen.scene.clutter.builders`: the builders, from instanced unit primitives
  (:mod:`vhgen.scene.meshkit`);
* :mod:`~vhgen.scene.clutter.items`: an item built from its kind and parameters (the
  manifest's parameters rebuild it exactly: :func:`build`) and the job's variants;
* :mod:`~vhgen.scene.clutter.place`: the frame's items against walls, in corners, on the
  walls and on the floor (imported from there: it reads the scene config).
"""

from vhgen.scene.clutter.items import ClutterShape, build, sample_params, smallest, variant
from vhgen.scene.clutter.kinds import CLUTTER_KINDS, KINDS, ClutterKind, clutter_kind

__all__ = ["CLUTTER_KINDS", "KINDS", "ClutterKind", "ClutterShape", "build", "clutter_kind",
           "sample_params", "smallest", "variant"]
