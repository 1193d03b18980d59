"""The ``avatars.outfit`` section of a job config: what people wear and carry, with the
probabilities and ranges every avatar's outfit is drawn from.

An outfit is drawn per avatar from the avatar's own seeded stream (after its shape; see
:func:`vhgen.pipeline.plan.avatar_params`) as a frozen :class:`Outfit` of typed records
(:class:`Top`, :class:`Outer`, :class:`Bottom`, :class:`Shoes`, :class:`Hair`,
:class:`Hat`, :class:`Carried`), which the dressing code (:mod:`vhgen.body.outfit`) reads
field by field; it becomes plain data only in the manifest (:meth:`Outfit.to_dict`, in
``avatar_params["outfit"]``), from which :meth:`Outfit.from_dict` and
:func:`vhgen.body.avatar.build_body` rebuild the same geometry. Seven items, drawn in
this order, each worn with its ``probability``; its kind is drawn by the ``kinds`` weights
and every parameter of the kind uniformly in its range (or, for a yes/no parameter, with
its chance):

======== ================================= =====================================
item     kinds                             parameters (see :data:`KINDS`)
======== ================================= =====================================
top      tank tshirt shirt jumper dress    sleeve, hem, collar, thickness_m
outer    jacket coat                       + gap_m, open, hood; coat: length, flare
bottom   trousers shorts skirt             length, rise, width / flare, thickness_m
shoes    shoes boots                       height, thickness_m, sole_m
hair     short medium long ponytail bun    volume_m, length_m, radius_m
hat      cap beanie brimmed                thickness_m, brim_m, crown_m
carried  shoulder_bag backpack hand_bag    width_m height_m depth_m / size_m /
         cup phone box                     radius_m, left (the side)
======== ================================= =====================================

Lengths along the body are in the chart's units (:mod:`vhgen.body.chart`): ``sleeve``
along the arm (0 shoulder, 0.5 elbow, 1 wrist; <= 0 sleeveless), ``length`` along the
leg (0 hip joint, 0.5 knee, 1 ankle), ``hem``/``rise`` in torso height (0 hip joints, 1
base of the neck), ``collar`` up the neck (0 none, 1 the skull), ``height`` of a shoe
along the leg (1 the ankle, 0.7 a boot to mid-calf); sizes in metres.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import Any, ClassVar

import numpy as np

from vhgen.errors import ConfigError
from vhgen.yamlio import check_keys, probability, range_value

ITEMS = ("top", "outer", "bottom", "shoes", "hair", "hat", "carried")
CARRIED_CLASS = "carried"  # the scene class of carried things that are not the person


@dataclass(frozen=True)
class Range:
    """A parameter drawn uniformly in [lo, hi]; ``bounds`` is what a config may ask."""

    lo: float
    hi: float
    bounds: tuple[float, float]


@dataclass(frozen=True)
class Chance:
    """A yes/no parameter, yes with probability ``p``."""

    p: float


Param = Range | Chance


def _r(lo: float, hi: float, bounds: tuple[float, float]) -> Range:
    return Range(lo, hi, bounds)


_SLEEVE, _HEM, _COLLAR = (-0.2, 1.1), (-1.0, 1.0), (0.0, 1.0)
_THICK, _LEN = (0.0, 0.1), (0.0, 1.1)
_SIZE = (0.002, 1.0)

# every kind of every item, its parameters in drawing order and their default ranges
KINDS: dict[str, dict[str, dict[str, Param]]] = {
    "top": {
        "tank": {"sleeve": _r(-0.1, -0.05, _SLEEVE), "hem": _r(-0.2, 0.0, _HEM),
                 "collar": _r(0.0, 0.0, _COLLAR), "thickness_m": _r(0.003, 0.008, _THICK)},
        "tshirt": {"sleeve": _r(0.15, 0.35, _SLEEVE), "hem": _r(-0.25, -0.05, _HEM),
                   "collar": _r(0.0, 0.0, _COLLAR), "thickness_m": _r(0.004, 0.012, _THICK)},
        "shirt": {"sleeve": _r(0.85, 1.0, _SLEEVE), "hem": _r(-0.3, -0.1, _HEM),
                  "collar": _r(0.0, 0.35, _COLLAR), "thickness_m": _r(0.005, 0.015, _THICK)},
        "jumper": {"sleeve": _r(0.9, 1.0, _SLEEVE), "hem": _r(-0.25, -0.05, _HEM),
                   "collar": _r(0.0, 0.8, _COLLAR), "thickness_m": _r(0.01, 0.025, _THICK)},
        "dress": {"sleeve": _r(-0.1, 0.4, _SLEEVE), "hem": _r(0.0, 0.0, _HEM),
                  "collar": _r(0.0, 0.0, _COLLAR), "thickness_m": _r(0.004, 0.012, _THICK)},
    },
    "outer": {
        "jacket": {"sleeve": _r(0.95, 1.02, _SLEEVE), "hem": _r(-0.35, -0.1, _HEM),
                   "collar": _r(0.1, 0.45, _COLLAR), "thickness_m": _r(0.015, 0.035, _THICK),
                   "gap_m": _r(0.08, 0.18, (0.0, 0.4)), "open": Chance(0.5),
                   "hood": Chance(0.25)},
        "coat": {"sleeve": _r(0.95, 1.02, _SLEEVE), "hem": _r(-0.15, -0.05, _HEM),
                 "collar": _r(0.1, 0.5, _COLLAR), "thickness_m": _r(0.02, 0.04, _THICK),
                 "gap_m": _r(0.08, 0.2, (0.0, 0.4)), "open": Chance(0.5),
                 "hood": Chance(0.2), "length": _r(0.35, 0.8, _LEN),
                 "flare": _r(0.0, 0.12, (0.0, 1.0))},
    },
    "bottom": {
        "trousers": {"length": _r(0.9, 1.0, _LEN), "rise": _r(0.15, 0.35, (-0.5, 1.0)),
                     "width": _r(0.0, 0.05, (0.0, 0.2)),
                     "thickness_m": _r(0.005, 0.015, _THICK)},
        "shorts": {"length": _r(0.2, 0.45, _LEN), "rise": _r(0.15, 0.35, (-0.5, 1.0)),
                   "width": _r(0.0, 0.03, (0.0, 0.2)),
                   "thickness_m": _r(0.004, 0.012, _THICK)},
        "skirt": {"length": _r(0.2, 0.85, _LEN), "rise": _r(0.2, 0.4, (-0.5, 1.0)),
                  "flare": _r(0.0, 0.3, (0.0, 1.0)), "thickness_m": _r(0.004, 0.012, _THICK)},
    },
    "shoes": {
        "shoes": {"height": _r(0.97, 1.02, (0.3, 1.2)), "thickness_m": _r(0.006, 0.012, _THICK),
                  "sole_m": _r(0.015, 0.03, (0.0, 0.08))},
        "boots": {"height": _r(0.6, 0.85, (0.3, 1.2)), "thickness_m": _r(0.008, 0.016, _THICK),
                  "sole_m": _r(0.02, 0.04, (0.0, 0.08))},
    },
    "hair": {
        "short": {"volume_m": _r(0.005, 0.02, (0.0, 0.08))},
        "medium": {"volume_m": _r(0.015, 0.035, (0.0, 0.08))},
        "long": {"volume_m": _r(0.015, 0.035, (0.0, 0.08)), "length_m": _r(0.1, 0.4, (0.0, 0.8))},
        "ponytail": {"volume_m": _r(0.004, 0.012, (0.0, 0.08)),
                     "length_m": _r(0.12, 0.3, (0.02, 0.8)),
                     "radius_m": _r(0.02, 0.035, (0.005, 0.1))},
        "bun": {"volume_m": _r(0.004, 0.012, (0.0, 0.08)),
                "radius_m": _r(0.035, 0.055, (0.005, 0.1))},
    },
    "hat": {
        "cap": {"thickness_m": _r(0.004, 0.008, _THICK), "brim_m": _r(0.05, 0.08, (0.0, 0.2))},
        "beanie": {"thickness_m": _r(0.01, 0.02, _THICK)},
        "brimmed": {"brim_m": _r(0.04, 0.09, (0.0, 0.2)), "crown_m": _r(0.02, 0.05, (0.0, 0.3))},
    },
    "carried": {
        "shoulder_bag": {"width_m": _r(0.25, 0.38, _SIZE), "height_m": _r(0.2, 0.3, _SIZE),
                         "depth_m": _r(0.06, 0.12, _SIZE), "left": Chance(0.5)},
        "backpack": {"width_m": _r(0.26, 0.34, _SIZE), "height_m": _r(0.36, 0.46, _SIZE),
                     "depth_m": _r(0.12, 0.2, _SIZE)},
        "hand_bag": {"width_m": _r(0.25, 0.38, _SIZE), "height_m": _r(0.2, 0.3, _SIZE),
                     "depth_m": _r(0.08, 0.14, _SIZE), "left": Chance(0.5)},
        "cup": {"radius_m": _r(0.035, 0.045, _SIZE), "height_m": _r(0.09, 0.14, _SIZE),
                "left": Chance(0.5)},
        "phone": {"width_m": _r(0.065, 0.078, _SIZE), "height_m": _r(0.14, 0.165, _SIZE),
                  "depth_m": _r(0.007, 0.01, _SIZE), "left": Chance(0.5)},
        "box": {"size_m": _r(0.12, 0.25, _SIZE), "left": Chance(0.5)},
    },
}

# what ``outfit: {}`` means: every item, with these chances and kinds
DEFAULT_PROBABILITY = {"top": 0.95, "outer": 0.35, "bottom": 1.0, "shoes": 0.9, "hair": 0.85,
                       "hat": 0.12, "carried": 0.25}
DEFAULT_WEIGHTS = {
    "top": {"tank": 1.0, "tshirt": 3.0, "shirt": 2.0, "jumper": 2.0, "dress": 1.0},
    "outer": {"jacket": 2.0, "coat": 1.0},
    "bottom": {"trousers": 5.0, "shorts": 1.0, "skirt": 1.5},
    "shoes": {"shoes": 3.0, "boots": 1.0},
    "hair": {"short": 3.0, "medium": 2.0, "long": 2.0, "ponytail": 1.0, "bun": 1.0},
    "hat": {"cap": 1.0, "beanie": 1.0, "brimmed": 1.0},
    "carried": {"shoulder_bag": 1.0, "backpack": 1.0, "hand_bag": 1.0, "cup": 1.0,
                "phone": 1.0, "box": 1.0},
}


class _Item:
    """What the records of worn items share: ``kind`` and the parameters :data:`KINDS`
    gives that kind (the fields of other kinds of the item stay at their defaults)."""

    ITEM: ClassVar[str]
    kind: str

    def to_dict(self) -> dict[str, Any]:
        """Plain data, as the manifest records it: ``kind`` and the kind's parameters in
        drawing order (a side as ``side``: "left" or "right")."""
        out: dict[str, Any] = {"kind": self.kind}
        for name in KINDS[self.ITEM][self.kind]:
            name = "side" if name == "left" else name
            out[name] = getattr(self, name)
        return out


@dataclass(frozen=True)
class Top(_Item):
    """A top (tank, tshirt, shirt, jumper, dress; the units: module docstring)."""

    ITEM: ClassVar[str] = "top"
    kind: str
    sleeve: float
    hem: float
    collar: float
    thickness_m: float


@dataclass(frozen=True)
class Outer(_Item):
    """A jacket or coat over the top; ``length`` and ``flare`` (of its hem below the
    hips) are a coat's."""

    ITEM: ClassVar[str] = "outer"
    kind: str
    sleeve: float
    hem: float
    collar: float
    thickness_m: float
    gap_m: float
    open: bool
    hood: bool
    length: float = 0.0
    flare: float = 0.0


@dataclass(frozen=True)
class Bottom(_Item):
    """Trousers or shorts (``width``: how much wider from the knee down) or a skirt
    (``flare``)."""

    ITEM: ClassVar[str] = "bottom"
    kind: str
    length: float
    rise: float
    thickness_m: float
    width: float = 0.0
    flare: float = 0.0


@dataclass(frozen=True)
class Shoes(_Item):
    """Shoes or boots."""

    ITEM: ClassVar[str] = "shoes"
    kind: str
    height: float
    thickness_m: float
    sole_m: float


@dataclass(frozen=True)
class Hair(_Item):
    """A hairstyle: ``volume_m`` on the scalp; ``length_m`` of long hair and a ponytail,
    ``radius_m`` of a ponytail and a bun."""

    ITEM: ClassVar[str] = "hair"
    kind: str
    volume_m: float
    length_m: float = 0.0
    radius_m: float = 0.0


@dataclass(frozen=True)
class Hat(_Item):
    """A hat: ``thickness_m`` of a cap's or beanie's crown, ``brim_m`` of a cap and a
    brimmed hat, ``crown_m`` of a brimmed hat."""

    ITEM: ClassVar[str] = "hat"
    kind: str
    thickness_m: float = 0.0
    brim_m: float = 0.0
    crown_m: float = 0.0


@dataclass(frozen=True)
class Carried(_Item):
    """A carried thing: its sizes (those of its kind, :data:`KINDS`), the ``side`` that
    carries it ("left", "right"; None for a backpack), and how it is labelled:
    ``as_person`` (the part that carries it, the person's class) or else label 0 and
    ``scene_class`` (recorded as ``class``)."""

    ITEM: ClassVar[str] = "carried"
    kind: str
    width_m: float = 0.0
    height_m: float = 0.0
    depth_m: float = 0.0
    radius_m: float = 0.0
    size_m: float = 0.0
    side: str | None = None
    as_person: bool = False
    scene_class: int = 0

    def to_dict(self) -> dict[str, Any]:
        """As :meth:`_Item.to_dict`, then ``as_person`` and ``class``."""
        return {**super().to_dict(), "as_person": self.as_person, "class": self.scene_class}


Item = Top | Outer | Bottom | Shoes | Hair | Hat | Carried


@dataclass(frozen=True)
class Outfit:
    """One avatar's outfit: each item a record, or None when not worn."""

    top: Top | None = None
    outer: Outer | None = None
    bottom: Bottom | None = None
    shoes: Shoes | None = None
    hair: Hair | None = None
    hat: Hat | None = None
    carried: Carried | None = None

    def worn(self) -> tuple[tuple[str, Item], ...]:
        """The items worn, (name, record) in the order of :data:`ITEMS`."""
        return tuple((f.name, getattr(self, f.name)) for f in fields(self)
                     if getattr(self, f.name) is not None)

    def to_dict(self) -> dict[str, dict[str, Any] | None]:
        """Plain data, as the manifest's ``avatar_params["outfit"]`` records it: {item:
        None or {"kind": ..., parameter: value}} for every item."""
        out: dict[str, dict[str, Any] | None] = {}
        for f in fields(self):
            rec = getattr(self, f.name)
            out[f.name] = rec.to_dict() if rec is not None else None
        return out

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Outfit:
        """Rebuild from :meth:`to_dict` output (a manifest's ``avatar_params.outfit``)."""
        return cls(**{name: None if d.get(name) is None else _record(name, d[name])
                      for name in ITEMS})


_RECORDS: dict[str, type[Item]] = {r.ITEM: r for r in (Top, Outer, Bottom, Shoes, Hair, Hat,
                                                       Carried)}


def _record(item: str, values: dict[str, Any]) -> Any:
    """The record of ``item`` from plain values (a draw, or :meth:`_Item.to_dict` output)."""
    return _RECORDS[item](**{"scene_class" if k == "class" else k: v
                             for k, v in values.items()})


@dataclass(frozen=True)
class ItemConfig:
    """One item: worn with ``probability``; ``kinds`` (name, weight) pairs; ``params``
    (kind, ((name, Range | Chance), ...)) in drawing order."""

    probability: float
    kinds: tuple[tuple[str, float], ...]
    params: tuple[tuple[str, tuple[tuple[str, Param], ...]], ...]

    def draw(self, rng: np.random.Generator) -> dict[str, Any] | None:
        """One draw of the item: None (not worn), or its kind and parameters (the values
        of its record)."""
        if not rng.uniform() < self.probability:
            return None
        w = np.array([k[1] for k in self.kinds])
        pick = int(np.searchsorted(np.cumsum(w) / w.sum(), rng.uniform(), side="right"))
        kind = self.kinds[min(pick, len(self.kinds) - 1)][0]
        out: dict[str, Any] = {"kind": kind}
        for name, p in dict(self.params)[kind]:
            if isinstance(p, Chance):
                yes = bool(rng.uniform() < p.p)
                if name == "left":
                    out["side"] = "left" if yes else "right"
                else:
                    out[name] = yes
            else:
                out[name] = float(rng.uniform(p.lo, p.hi))
        return out


def _default_item(item: str) -> ItemConfig:
    return ItemConfig(DEFAULT_PROBABILITY[item], tuple(DEFAULT_WEIGHTS[item].items()),
                      tuple((k, tuple(v.items())) for k, v in KINDS[item].items()))


@dataclass(frozen=True)
class OutfitConfig:
    """``avatars.outfit``: None items are never worn; ``enabled`` False (no ``outfit``
    key) draws nothing at all, so configs without it keep their avatars byte for byte.
    ``carried_as_person``: carried things are labelled as the body part carrying them and
    belong to the person's instance and class; else they have label 0, no instance and
    the scene class ``carried_class`` (the job config sets its id)."""

    enabled: bool = False
    items: tuple[tuple[str, ItemConfig | None], ...] = ()
    carried_as_person: bool = False
    carried_class: int = 0

    @property
    def has_own_class(self) -> bool:
        """Whether carried things are drawn and get a scene class of their own."""
        item = dict(self.items).get("carried")
        return self.enabled and item is not None and item.probability > 0 and \
            not self.carried_as_person

    def with_class(self, class_id: int) -> OutfitConfig:
        """The same config with carried things in scene class ``class_id``."""
        return replace(self, carried_class=int(class_id))

    def sample(self, rng: np.random.Generator) -> Outfit:
        """One avatar's outfit, its items drawn from ``rng`` in the order of
        :data:`ITEMS`."""
        worn: dict[str, Any] = {}
        for name, item in self.items:
            drawn = item.draw(rng) if item is not None else None
            worn[name] = _record(name, drawn) if drawn is not None else None
        top, outer = worn.get("top"), worn.get("outer")
        if top is not None and top.kind == "dress":
            # a dress is a top and a skirt in one: its skirt comes from the bottom's ranges
            bottom = dict(self.items).get("bottom") or _default_item("bottom")
            skirt = dict(bottom.params)["skirt"]
            drawn = ItemConfig(1.0, (("skirt", 1.0),), (("skirt", skirt),)).draw(rng)
            worn["bottom"] = _record("bottom", drawn) if drawn is not None else None
        if outer is not None and outer.open and top is None:
            worn["outer"] = replace(outer, open=False)  # nothing under it to show
        if worn.get("carried") is not None:
            worn["carried"] = replace(worn["carried"], as_person=self.carried_as_person,
                                      scene_class=0 if self.carried_as_person
                                      else self.carried_class)
        return Outfit(**worn)


def _param(v: Any, default: Param, src, where: str) -> Param:
    if isinstance(default, Chance):
        return Chance(probability(v, src, where))
    lo, hi = range_value(v, src, where, lo=default.bounds[0], hi=default.bounds[1])
    return Range(lo, hi, default.bounds)


def _item(name: str, d: Any, src, prefix: str) -> ItemConfig | None:
    if d is False or d is None:
        return None
    if d is True:
        d = {}
    kinds = KINDS[name]
    check_keys(d, {"probability", "kinds", *kinds}, set(), src, prefix)
    prob = probability(d.get("probability", DEFAULT_PROBABILITY[name]), src, prefix + "probability")
    raw = d.get("kinds", DEFAULT_WEIGHTS[name])
    if isinstance(raw, list):
        raw = {k: 1.0 for k in raw} if all(isinstance(k, str) for k in raw) else raw
    if not isinstance(raw, dict) or not raw:
        raise ConfigError(src, prefix + "kinds", f"must be a list of {', '.join(kinds)} or a "
                          f"mapping of them to weights, got {raw!r}")
    weights = []
    for k, w in raw.items():
        if k not in kinds:
            raise ConfigError(src, f"{prefix}kinds.{k}", f"unknown {name} kind (one of "
                              f"{', '.join(kinds)})")
        if isinstance(w, bool) or not isinstance(w, (int, float)) or w < 0:
            raise ConfigError(src, f"{prefix}kinds.{k}", f"weight must be >= 0, got {w!r}")
        weights.append((str(k), float(w)))
    if sum(w for _, w in weights) <= 0:
        raise ConfigError(src, prefix + "kinds", "all weights are 0")
    params = []
    for kind, defaults in kinds.items():
        over = d.get(kind) or {}
        check_keys(over, set(defaults), set(), src, f"{prefix}{kind}.")
        params.append((kind, tuple((p, _param(over[p], dv, src, f"{prefix}{kind}.{p}")
                                    if p in over else dv) for p, dv in defaults.items())))
    return ItemConfig(prob, tuple(weights), tuple(params))


def parse_outfit(d: Any, src, prefix: str = "avatars.outfit.") -> OutfitConfig:
    """The ``avatars.outfit`` section (None: absent, no outfits). Every field is checked
    (errors name ``src`` and the field); unknown keys are refused. An empty mapping is
    every item with its default chance, kinds and ranges; ``item: false`` never wears it."""
    if d is None:
        return OutfitConfig()
    if d is True:
        d = {}
    check_keys(d, {*ITEMS, "carried_as_person"}, set(), src, prefix)
    as_person = d.get("carried_as_person", False)
    if not isinstance(as_person, bool):
        raise ConfigError(src, prefix + "carried_as_person",
                          f"must be true or false, got {as_person!r}")
    items = tuple((n, _item(n, d.get(n, {}), src, f"{prefix}{n}.")) for n in ITEMS)
    return OutfitConfig(True, items, as_person)


def default_outfit_config() -> OutfitConfig:
    """``outfit: {}``: every item with its default chance, kinds and ranges."""
    return OutfitConfig(True, tuple((n, _default_item(n)) for n in ITEMS))


__all__ = ["CARRIED_CLASS", "ITEMS", "KINDS", "Bottom", "Carried", "Chance", "Hair", "Hat",
           "Item", "ItemConfig", "Outer", "Outfit", "OutfitConfig", "Range", "Shoes", "Top",
           "default_outfit_config", "parse_outfit"]
