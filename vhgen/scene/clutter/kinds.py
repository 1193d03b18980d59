"""The clutter kinds: one :class:`ClutterKind` record per kind, in one registry (pure).

A record is everything vhgen knows about a kind: the ranges its sizes are drawn from, its
builder (:mod:`vhgen.scene.clutter.builders`), how it stands in a room (placement modes and
their weights), how much rarer a second one in the same frame is, whether it is built
about its vertical axis, whether its surface gives a measurement, whether it may rise
through the ceiling, the opening it cuts in its wall, and whether its class is the class
of the things standing on other items. Placement (:mod:`vhgen.scene.clutter.place`), the
item builder (:mod:`vhgen.scene.clutter.items`) and the config read the record; nothing
else names a kind.

Adding a kind: write its builder in :mod:`vhgen.scene.clutter.builders` and append one
record to :data:`SHIPPED` (at the end: a kind's position seeds the job's variants of it,
so the kinds before it keep their shapes), then add it to the kinds table of
``docs/scenes.md``. Configs that list no ``kinds`` take every kind, so their frames
change: record the new bytes with ``python tests/pipeline/test_output_bytes.py``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields
from types import MappingProxyType
from typing import Any

import numpy as np

import vhgen.scene.clutter.builders as b
from vhgen.scene.meshkit import Kit

# where an item stands: "wall" (its back to a wall, anywhere along it), "corner" (its back
# to a wall and a side to the next), "floor" (anywhere, any heading). Wall-mounted kinds
# (shelf, picture, window, radiator) are "wall" kinds whose footprints start above the
# floor; a door is a wall kind that cuts an opening.
PLACEMENT_MODES = ("wall", "corner", "floor")
# each item of a kind already drawn for the frame multiplies that kind's weight by its
# ``repeat``; a config that lists one kind still gets all its items, as weights are shares
REPEAT_DEFAULT = 0.5
# parameters every item has besides its kind's ranges (see items.sample_params)
COMMON_PARAMS = ("fill", "seed")

Builder = Callable[[Kit, dict, np.random.Generator], Any]
Opening = Callable[[Mapping[str, float]], tuple[float, float, float, float]]


@dataclass(frozen=True)
class ClutterKind:
    """One clutter kind.

    name : the kind's name in configs and the manifest (``scene.clutter.kinds``)
    ranges : parameter -> (low, high): the top-level sizes, drawn uniformly from the scene
        stream in this order (see :func:`vhgen.scene.clutter.items.sample_params`)
    builder : ``builder(kit, params, generator)`` adds the item's meshes to the kit in the
        item's own frame and may return explicit footprints for its first groups
    modes : ((mode, weight), ...): how it stands (:data:`PLACEMENT_MODES`), with weights
    repeat : each item of this kind already in the frame multiplies its weight by this
    centred : built about the y axis (a plant, a lamp): moved so that its box is centred
        in x and its back is on z = 0
    returns : False when its surface gives no measurement (window glass): its pixels lose
        their depth, so its class must be its own
    pierces_ceiling : may rise above the walls (stairs to an upper floor)
    opening : params -> (x0, x1, y0, y1) of the hole it cuts in its wall (a door), or None
    surface_things : its entry's class is also the class of the things standing on other
        items (the ``objects`` kind)
    """

    name: str
    ranges: Mapping[str, tuple[float, float]]
    builder: Builder
    modes: tuple[tuple[str, float], ...]
    repeat: float = REPEAT_DEFAULT
    centred: bool = False
    returns: bool = True
    pierces_ceiling: bool = False
    opening: Opening | None = field(default=None)
    surface_things: bool = False

    def __post_init__(self) -> None:
        where = f"clutter kind {self.name!r}"
        if not self.name.isidentifier():
            raise TypeError(f"{where}: the name must be a word (letters, digits, _)")
        if not self.ranges:
            raise TypeError(f"{where}: no ranges (its sizes)")
        for k, (lo, hi) in self.ranges.items():
            if k in COMMON_PARAMS or not lo <= hi:
                raise TypeError(f"{where}: range {k}: ({lo}, {hi}) (a name other than "
                                f"{', '.join(COMMON_PARAMS)}, low <= high)")
        # read-only, in the order given (the order of the draws)
        object.__setattr__(self, "ranges", MappingProxyType(dict(self.ranges)))
        if not callable(self.builder):
            raise TypeError(f"{where}: the builder must be a function (kit, params, rng)")
        if not self.modes or any(m not in PLACEMENT_MODES or not w > 0
                                 for m, w in self.modes):
            raise TypeError(f"{where}: modes {self.modes!r} must be (mode, weight > 0) "
                            f"pairs of the modes {', '.join(PLACEMENT_MODES)}")
        if not 0 < self.repeat <= 1:
            raise TypeError(f"{where}: repeat {self.repeat!r} must be in (0, 1]")
        for f in fields(self):
            if f.type == "bool" and not isinstance(getattr(self, f.name), bool):
                raise TypeError(f"{where}: {f.name} must be true or false")
        if self.opening is not None and not callable(self.opening):
            raise TypeError(f"{where}: opening must be a function of the params")


def _registry(kinds: tuple[ClutterKind, ...]) -> Mapping[str, ClutterKind]:
    out: dict[str, ClutterKind] = {}
    for k in kinds:
        if k.name in out:
            raise TypeError(f"clutter kind {k.name!r} is registered twice")
        out[k.name] = k
    return MappingProxyType(out)


SHIPPED: tuple[ClutterKind, ...] = (
    ClutterKind("bookcase", {"w": (0.6, 1.2), "d": (0.28, 0.4), "h": (1.1, 2.2),
                             "spacing": (0.28, 0.4), "back": (0, 1)},
                b.bookcase, (("wall", 0.7), ("corner", 0.3))),
    ClutterKind("shelf", {"w": (0.5, 1.2), "d": (0.18, 0.3), "y": (0.9, 1.5),
                          "boards": (1, 3.999), "spacing": (0.3, 0.42)},
                b.shelf, (("wall", 1.0),)),
    ClutterKind("cabinet", {"w": (0.6, 1.8), "d": (0.35, 0.5), "h": (0.5, 1.1),
                            "doors": (1, 4.999)},
                b.cabinet, (("wall", 0.8), ("corner", 0.2))),
    ClutterKind("desk", {"w": (1.0, 1.6), "d": (0.55, 0.8), "h": (0.72, 0.76), "chair": (0, 1),
                         "monitor": (0.45, 0.7)},
                b.desk, (("wall", 0.7), ("corner", 0.3)), repeat=0.2),
    ClutterKind("tv", {"w": (1.0, 1.8), "d": (0.35, 0.45), "h": (0.4, 0.6),
                       "screen": (0.8, 1.45)},
                b.tv, (("wall", 1.0),), repeat=0.05),
    ClutterKind("table", {"w": (0.8, 1.6), "d": (0.6, 1.0), "h": (0.45, 0.8)},
                b.table, (("floor", 0.5), ("wall", 0.5)), repeat=0.3),
    ClutterKind("plant", {"height": (0.5, 1.9), "pot_r": (0.1, 0.2), "pot_h": (0.15, 0.35),
                          "branches": (3, 9.999), "leaves": (5, 14.999), "leaf": (0.06, 0.2)},
                b.plant, (("corner", 0.5), ("wall", 0.3), ("floor", 0.2)), centred=True),
    ClutterKind("stairs", {"steps": (6, 11.999), "rise": (0.16, 0.2), "run": (0.24, 0.3),
                           "width": (0.75, 1.0), "open": (0, 1), "dir": (0, 1)},
                b.stairs, (("corner", 0.6), ("wall", 0.4)), repeat=0.05,
                pierces_ceiling=True),
    ClutterKind("lamp", {"height": (1.3, 1.8), "shade_r": (0.15, 0.25), "shade_h": (0.18, 0.3),
                         "taper": (0.5, 0.95)},
                b.lamp, (("corner", 0.5), ("wall", 0.3), ("floor", 0.2)), centred=True),
    ClutterKind("radiator", {"w": (0.5, 1.6), "h": (0.4, 0.7), "y": (0.08, 0.2),
                             "d": (0.06, 0.12), "pitch": (0.045, 0.08)},
                b.radiator, (("wall", 1.0),)),
    ClutterKind("window", {"w": (0.8, 2.0), "h": (1.0, 1.5), "sill": (0.7, 1.0),
                           "frame": (0.05, 0.09), "mullions": (0, 2.999), "sill_d": (0.1, 0.2)},
                b.window, (("wall", 1.0),), returns=False),
    ClutterKind("curtain", {"w": (0.4, 1.4), "top": (2.0, 2.3), "bottom": (0.0, 0.3),
                            "period": (0.08, 0.16), "amplitude": (0.02, 0.06)},
                b.curtain, (("wall", 0.5), ("corner", 0.5))),
    ClutterKind("door", {"w": (0.78, 0.95), "h": (1.98, 2.1), "angle_deg": (0, 100),
                         "hinge": (0, 1), "corridor_d": (1.0, 3.0), "corridor_w": (0.2, 1.5)},
                b.door, (("wall", 1.0),), repeat=0.1, opening=b.door_opening),
    ClutterKind("boxes", {"w": (0.3, 0.7), "d": (0.25, 0.6), "h": (0.2, 0.5),
                          "count": (1, 3.999)},
                b.boxes, (("wall", 0.4), ("corner", 0.3), ("floor", 0.3))),
    ClutterKind("bag", {"w": (0.3, 0.6), "h": (0.25, 0.5), "d": (0.15, 0.3), "handles": (0, 1)},
                b.bag, (("wall", 0.4), ("floor", 0.6))),
    ClutterKind("objects", {"w": (0.4, 1.0), "d": (0.3, 0.7), "count": (3, 8.999)},
                b.objects, (("floor", 0.6), ("wall", 0.4)), surface_things=True),
    ClutterKind("picture", {"w": (0.3, 1.2), "h": (0.3, 0.9), "y": (1.3, 1.75),
                            "t": (0.02, 0.05)},
                b.picture, (("wall", 1.0),)),
    # free-standing seats: a swivel chair (high curved back, maybe arms and a headrest)
    # or an upholstered armchair, as big as a seated person
    ClutterKind("chair", {"style": (0, 1), "w": (0.46, 0.62), "seat": (0.42, 0.52),
                          "back": (0.45, 0.85), "curve": (0.0, 0.5), "recline": (0.0, 0.3),
                          "arms": (0, 1)},
                b.chair, (("floor", 0.6), ("wall", 0.2), ("corner", 0.2)), centred=True),
    # a coat stand with coats, bags and hats hanging from its hooks: person-sized
    ClutterKind("coat_stand", {"height": (1.6, 1.9), "coats": (0, 3.999), "hooks": (3, 6.999),
                               "coat_len": (0.5, 1.1)},
                b.coat_stand, (("corner", 0.5), ("wall", 0.3), ("floor", 0.2)), centred=True),
)
# the registry: name -> record, in the order of SHIPPED
KINDS: Mapping[str, ClutterKind] = _registry(SHIPPED)
CLUTTER_KINDS: tuple[str, ...] = tuple(KINDS)


def clutter_kind(name: str) -> ClutterKind:
    """The record of the kind ``name``; ValueError naming the kinds there are, and how to
    add one, for any other name."""
    try:
        return KINDS[name]
    except KeyError:
        raise ValueError(f"unknown clutter kind {name!r}: the kinds are "
                         f"{', '.join(KINDS)} (a new kind is a builder in "
                         f"vhgen/scene/clutter/builders.py and a ClutterKind record in "
                         f"vhgen/scene/clutter/kinds.py)") from None


def kind_index(name: str) -> int:
    """The kind's position in the registry (part of its variants' seeds)."""
    return CLUTTER_KINDS.index(clutter_kind(name).name)
