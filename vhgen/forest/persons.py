"""Person scores of labelled frames: by distance, by group size, per person instance.

What is scored is a *called-person* mask, (H, W) bool: by default the forest's labels > 0;
with the segmentation stage (or any later stage) its person mask. The truth is a
frame's person instances, (H, W) uint8 (0 = no person, k = the k-th person: a store's
``instances`` array; a store without one gives ``labels > 0`` as one person). Only pixels
with a measurement (depth > 0) count. No threshold here was fitted to any data:

- a person is **visible** when at least one of its pixels has a measurement; a frame's
  **group size** is the number of its visible people, binned ``1``, ``2-3``, ``4-6``
  (``0`` and ``>6`` when such frames occur; ``?`` when the truth has no instances);
- a person's **distance** is the median depth of its visible pixels, in metres, binned
  ``1-2``, ``2-3``, ``3-4.5`` (half-open: [1, 2), [2, 3), [3, 4.5); ``<1`` and ``>4.5``
  when such people occur): the ranges of the issue;
- a person is **found** when at least half of its visible pixels are called a person
  (:data:`FOUND_SHARE`, the rule of the issue); ``instance_recall`` = found / visible people;
  per group bin, ``everyone_found`` = frames in which every visible person is found /
  frames with someone visible (a frame of five people counts only with all five found);
- a person **touches** another when one of its pixels is a 4-neighbour of another
  person's pixel in the instance image (with or without measurement: the sensor's
  shadow between two overlapping people does not part them);
- ``recall`` (pixels): person pixels called a person / person pixels, per distance bin
  over the pixels of the people whose distance falls in the bin;
- ``precision`` (pixels): called pixels that are a person / called pixels; per distance
  bin over the called pixels whose *own* depth falls in the bin (a wrong call has no
  person to take a distance from), per group bin over the called pixels of its frames;
- where the calls are people instances (the segmentation stage's, not a bare mask), a
  **false person** is a called instance less than half of whose measured pixels are a
  person's (:data:`FALSE_SHARE`): a bookcase called a person. ``false_per_frame`` (per
  group bin and overall) = false people / frames, the false positives per image of
  pedestrian detection (Dollar et al. 2012); ``instance_precision`` = 1 - false people /
  called instances (a person cut in two is two true calls). Pixel precision weighs a
  false person by its size, so one object near the camera outweighs many far ones; these
  count them.
- a frame's **background called** is the share of its measured pixels on no person that
  are called a person; ``background_over`` (per group bin and overall) counts the frames
  in which it is more than :data:`BACKGROUND_SHARE` (the issue's target for real rooms
  with nobody: at most 3% of the background called a body part in every room), and
  ``background_over_share`` their share of the frames: a held-out stand-in for "every
  room", where pixel precision pools all frames into one number; ``background_frames``
  names those frames (store, frame, background called).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

DISTANCE_EDGES_M = (1.0, 2.0, 3.0, 4.5)
DISTANCE_BINS = ("<1", "1-2", "2-3", "3-4.5", ">4.5")
MAIN_DISTANCE_BINS = ("1-2", "2-3", "3-4.5")  # always reported, the others when present
GROUP_BINS = ((0, 0, "0"), (1, 1, "1"), (2, 3, "2-3"), (4, 6, "4-6"))
MAIN_GROUP_BINS = ("1", "2-3", "4-6")
UNKNOWN_GROUP = "?"
FOUND_SHARE = 0.5
FALSE_SHARE = FOUND_SHARE  # a false person: the mirror of a found one
BACKGROUND_SHARE = 0.03  # a frame's background called a person: the target


def distance_bin(distance_m: float) -> str:
    """The bin name of a distance in metres (see the module docstring)."""
    return DISTANCE_BINS[int(np.searchsorted(DISTANCE_EDGES_M, distance_m, side="right"))]


def group_bin(people: int | None) -> str:
    """The bin name of a group size (None: unknown, ``?``)."""
    if people is None:
        return UNKNOWN_GROUP
    for lo, hi, name in GROUP_BINS:
        if lo <= people <= hi:
            return name
    return f">{GROUP_BINS[-1][1]}"


def neighbour_pairs(ids: np.ndarray) -> np.ndarray:
    """(K, 2) int64: every ordered pair (a, b) of different non-zero ids of the (H, W)
    image ``ids`` that are 4-neighbours somewhere, each pair once."""
    pairs = [np.stack([a[m], b[m]], 1).astype(np.int64)
             for a, b in ((ids[:, :-1], ids[:, 1:]), (ids[:-1], ids[1:]))
             for m in [(a > 0) & (b > 0) & (a != b)]]
    both = np.concatenate(pairs)
    return np.unique(np.concatenate([both, both[:, ::-1]]), axis=0)


def _touching(instances: np.ndarray) -> np.ndarray:
    """(256,) bool: instance ids with a 4-neighbour of another instance (not 0)."""
    out = np.zeros(256, bool)
    out[neighbour_pairs(instances)[:, 0]] = True
    return out


@dataclass(frozen=True)
class FramePeople:
    """One frame's person counts (see :func:`frame_people`)."""

    group: str
    people: list[dict]  # per visible person: instance, pixels, called, distance_m, touching
    called_person: np.ndarray  # (len(DISTANCE_BINS),) int64, by the pixel's own depth
    called_other: np.ndarray  # (len(DISTANCE_BINS),) int64, called pixels on no person
    false_people: int | None = None  # called instances mostly not a person (None: a mask)
    called_people: int | None = None  # called instances with a measured pixel
    background: int = 0  # measured pixels on no person

    @property
    def background_called(self) -> float:
        """The share of the frame's measured pixels on no person called a person."""
        return float(self.called_other.sum()) / self.background if self.background else 0.0


def frame_people(called: np.ndarray, depth_mm: np.ndarray, instances: np.ndarray,
                 *, has_instances: bool = True) -> FramePeople:
    """Score one frame. ``called`` (H, W) bool, or the called people as instance ids
    (any integer type, 0 = none: false people are counted), ``depth_mm`` (H, W) uint16
    (0 = no measurement), ``instances`` (H, W) uint8 (0 = no person); ``has_instances``
    False: the instances are ``labels > 0`` (one person of unknown group size)."""
    depth = np.asarray(depth_mm)
    inst = np.asarray(instances).astype(np.uint8, copy=False)
    valid = depth > 0
    vinst = np.where(valid, inst, 0)
    ids = np.asarray(called)
    called = ids.astype(bool) & valid
    false_people = called_people = None
    if ids.dtype != bool:
        # per called instance: its measured pixels, and those on a person
        own = np.where(called, ids, 0).ravel().astype(np.int64)
        size = np.bincount(own)
        on = np.bincount(own, weights=(vinst > 0).ravel())
        false_people = int(((size[1:] > 0) & (on[1:] < FALSE_SHARE * size[1:])).sum())
        called_people = int((size[1:] > 0).sum())
    pixels = np.bincount(vinst.ravel(), minlength=256)
    hit = np.bincount(vinst[called], minlength=256)
    touching = _touching(inst)
    people = []
    for k in np.flatnonzero(pixels[1:]) + 1:
        d = float(np.median(depth[vinst == k])) / 1000.0
        people.append({"instance": int(k), "pixels": int(pixels[k]), "called": int(hit[k]),
                       "distance_m": round(d, 4), "touching": bool(touching[k])})
    px_bin = np.searchsorted(DISTANCE_EDGES_M, depth / 1000.0, side="right")
    on_person = vinst > 0
    nb = len(DISTANCE_BINS)
    return FramePeople(
        group_bin(len(people) if has_instances else None), people,
        np.bincount(px_bin[called & on_person], minlength=nb).astype(np.int64),
        np.bincount(px_bin[called & ~on_person], minlength=nb).astype(np.int64),
        false_people, called_people, int((valid & ~on_person).sum()))


def _ratio(a: int, b: int) -> float | None:
    return a / b if b else None


@dataclass
class _Tally:
    frames: int = 0
    people: int = 0
    found: int = 0
    pixels: int = 0
    called: int = 0
    called_person: int = 0  # called pixels that are a person (precision's numerator)
    called_other: int = 0  # called pixels that are no person
    with_people: int = 0  # frames with someone visible
    everyone_found: int = 0  # of those, frames whose every visible person is found
    counted: int = 0  # frames whose called people are instances (false people counted)
    false_people: int = 0
    called_people: int = 0
    background_over: int = 0  # frames with more than BACKGROUND_SHARE of it called

    def row(self, name: str, with_frames: bool, with_precision: bool) -> dict:
        r: dict = {"bin": name}
        if with_frames:
            r.update({"frames": self.frames, "frames_everyone_found": self.everyone_found,
                      "everyone_found": _ratio(self.everyone_found, self.with_people),
                      "background_over": self.background_over,
                      "background_over_share": _ratio(self.background_over, self.frames)})
            if self.counted:
                r.update({"called_people": self.called_people,
                          "false_people": self.false_people,
                          "false_per_frame": self.false_people / self.counted,
                          "instance_precision": _ratio(
                              self.called_people - self.false_people, self.called_people)})
        r.update({"people": self.people, "found": self.found,
                  "instance_recall": _ratio(self.found, self.people),
                  "pixels": self.pixels, "recall": _ratio(self.called, self.pixels)})
        if with_precision:
            r.update({"called_person": self.called_person, "called_other": self.called_other,
                      "precision": _ratio(self.called_person,
                                          self.called_person + self.called_other)})
        return r


@dataclass
class PeopleScore:
    """Accumulates :func:`frame_people` over frames; :meth:`result` gives the scores."""

    called_by: str = "forest labels > 0"
    truth: set[str] = field(default_factory=set)
    by_distance: dict[str, _Tally] = field(default_factory=dict)
    by_group: dict[str, _Tally] = field(default_factory=dict)
    by_contact: dict[str, _Tally] = field(default_factory=dict)
    overall: _Tally = field(default_factory=_Tally)
    instances: list[list] = field(default_factory=list)
    background_frames: list[list] = field(default_factory=list)  # over BACKGROUND_SHARE

    def add(self, fp: FramePeople, where: tuple[str, int], has_instances: bool = True
            ) -> None:
        """Add a frame; ``where`` = (store, frame) names it in the per-person rows."""
        self.truth.add("instances" if has_instances else "labels")
        if fp.background_called > BACKGROUND_SHARE:
            self.background_frames.append([where[0], where[1],
                                           round(fp.background_called, 4)])
        g = self.by_group.setdefault(fp.group, _Tally())
        tallies = [g, self.overall]
        found = [p["called"] >= FOUND_SHARE * p["pixels"] for p in fp.people]
        for t in tallies:
            t.frames += 1
            t.called_person += int(fp.called_person.sum())
            t.called_other += int(fp.called_other.sum())
            t.with_people += int(bool(found))
            t.everyone_found += int(bool(found) and all(found))
            t.background_over += int(fp.background_called > BACKGROUND_SHARE)
            if fp.false_people is not None and fp.called_people is not None:
                t.counted += 1
                t.false_people += fp.false_people
                t.called_people += fp.called_people
        for b, name in enumerate(DISTANCE_BINS):
            d = self.by_distance.setdefault(name, _Tally())
            d.called_person += int(fp.called_person[b])
            d.called_other += int(fp.called_other[b])
        for p, hit in zip(fp.people, found, strict=True):
            contact = "touching" if p["touching"] else "apart"
            for t in (g, self.overall, self.by_distance[distance_bin(p["distance_m"])],
                      self.by_contact.setdefault(contact, _Tally())):
                t.people += 1
                t.found += int(hit)
                t.pixels += p["pixels"]
                t.called += p["called"]
            self.instances.append([where[0], where[1], p["instance"], p["pixels"],
                                   p["distance_m"], round(p["called"] / p["pixels"], 4),
                                   bool(hit), p["touching"]])

    def result(self) -> dict:
        """The scores as plain dicts (the ``people`` entry of ``forest eval``'s JSON)."""
        def rows(tallies: dict[str, _Tally], order: tuple[str, ...], main: tuple[str, ...],
                 with_frames: bool, with_precision: bool) -> list[dict]:
            names = [n for n in order if n in main or
                     (n in tallies and (tallies[n].people or tallies[n].frames
                                        or tallies[n].called_other))]
            names += sorted(n for n in tallies if n not in order and n not in names)
            return [tallies.get(n, _Tally()).row(n, with_frames, with_precision)
                    for n in names]

        groups = tuple(n for _, _, n in GROUP_BINS) + (UNKNOWN_GROUP,)
        return {
            "called": self.called_by,
            "truth": "+".join(sorted(self.truth)),
            "found_share": FOUND_SHARE,
            "background_share": BACKGROUND_SHARE,
            "distance_edges_m": list(DISTANCE_EDGES_M),
            "overall": self.overall.row("all", True, True),
            "by_distance": rows(self.by_distance, DISTANCE_BINS, MAIN_DISTANCE_BINS,
                                False, True),
            "by_group": rows(self.by_group, groups, MAIN_GROUP_BINS, True, True),
            "by_contact": rows(self.by_contact, ("touching", "apart"), ("touching", "apart"),
                               False, False),
            "instance_columns": ["store", "frame", "instance", "pixels", "distance_m",
                                 "called_share", "found", "touching"],
            "instances": self.instances,
            "background_frame_columns": ["store", "frame", "background_called"],
            "background_frames": self.background_frames,
        }


def table(res: dict) -> str:
    """The person scores of :meth:`PeopleScore.result` as text."""
    def f(v: float | None) -> str:
        return "-" if v is None else f"{v:.3f}"

    false = "false_per_frame" in res["overall"]
    head = (f"{'frames':>7} {'people':>7} {'found':>6} {'inst.recall':>11} "
            f"{'px recall':>9} {'px precision':>12} {'all found':>9} {'bg>3%':>6}"
            + (f" {'false/frame':>11} {'inst.precision':>14}" if false else ""))
    lines = [f"person scores (called: {res['called']}; found: at least "
             f"{res['found_share']:.0%} of a person's pixels called; all found: frames in "
             f"which every person is; bg>3%: frames with more than "
             f"{res['background_share']:.0%} of their background called a person; "
             + ("false/frame: called people mostly not a person, per frame; inst.precision: "
                "the other called people's share; " if false else "")
             + f"truth: {res['truth']})"]

    def block(title: str, rows: list[dict], suffix: str = "") -> None:
        lines.append(f"{title:<16} {head}")
        for r in rows:
            lines.append(f"{r['bin'] + suffix:<16} {r.get('frames', ''):>7} {r['people']:>7} "
                         f"{r['found']:>6} {f(r['instance_recall']):>11} {f(r['recall']):>9} "
                         f"{f(r.get('precision')):>12} {f(r.get('everyone_found')):>9} "
                         f"{f(r.get('background_over_share')):>6}"
                         + (f" {f(r.get('false_per_frame')):>11} "
                            f"{f(r.get('instance_precision')):>14}" if false else ""))

    block("distance", res["by_distance"], " m")
    block("contact", res["by_contact"])
    block("group size", [*res["by_group"], res["overall"]])
    return "\n".join(lines)
