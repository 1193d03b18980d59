"""What a BVH joint name says: body side and body part, across the common conventions.

Names are split into lower-case tokens at separators (space ``_ . - :``) and camel-case
boundaries, tool prefixes are dropped (``mixamorig:``, ``Bip01``, ``Character1_``, Rigify
``DEF-``), a side token at either end is read as the side (``Left``/``L``/``l``, Kinect's
``HipLeft``, Bandai's ``UpperLeg_L``, Blender's ``thigh.L``), and the rest is looked up in a
synonym table. Covered: CMU MB (``LeftUpLeg``, ``LHipJoint``), CMU daz/Poser (``lThigh``,
``rShldr``, ``abdomen``), 3ds Max Biped (``Bip01 L Thigh``, ``Calf``), Mixamo/Rokoko,
Perception Neuron (``Spine3``, ``InHandIndex``), Xsens MVN (``RightUpperLeg``, ``L5``,
``T8``), Unity/Bandai (``UpperArm_L``, ``LowerLeg_L``), SFU/Biovision (``LeftHip``,
``LeftKnee``, ``LeftCollar``), Kinect v1/v2 (``HipLeft``, ``ShoulderCenter``,
``SpineBase``). A name gives *evidence* (part -> score); the hierarchy and the geometry
decide (see :mod:`vhgen.mocap.automap`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

_TOKEN = re.compile(r"[A-Z]+(?=[A-Z][a-z])|[A-Z]?[a-z]+|[A-Z]+|\d+")
_PREFIX_TOKENS = {"mixamorig", "bip", "bip01", "bip001", "character", "def", "org", "mch",
                  "jnt", "bone", "rig", "skel"}
_LEFT = {"l", "left", "lft"}
_RIGHT = {"r", "right", "rt", "rgt"}
_FINGER = {"thumb", "index", "middle", "ring", "pinky", "pinkie", "little", "finger",
           "fingers", "carpal", "metacarpal", "fingerbase"}
_END = {"end", "nub", "tip", "top", "site", "endsite", "dummy"}
_TWIST = {"roll", "twist", "share", "helper", "aux"}
_MODIFIERS = ("bend", "lower", "upper", "base", "joint")  # daz Genesis lThighBend, chestUpper

# base name (side and trailing digits removed, tokens joined) -> {part: score}
# Parts: pelvis hipjoint thigh shin foot toe spine chest neck head clavicle upperarm forearm
# hand. Scores near 1 are unambiguous; lower ones are one reading of an ambiguous name.
_UNSIDED: dict[str, dict[str, float]] = {
    "hips": {"pelvis": 1.0}, "hip": {"pelvis": 0.9}, "pelvis": {"pelvis": 1.0},
    "hipcenter": {"pelvis": 1.0}, "spinebase": {"pelvis": 0.9}, "hipsroot": {"pelvis": 0.8},
    "spine": {"spine": 1.0}, "lowerback": {"spine": 1.0}, "abdomen": {"spine": 1.0},
    "ab": {"spine": 0.8}, "back": {"spine": 0.7}, "torso": {"spine": 0.7},
    "spinemid": {"spine": 1.0}, "spinelower": {"spine": 1.0}, "waist": {"spine": 0.8},
    "l": {"spine": 0.9}, "t": {"spine": 0.9},  # Xsens L5, L3, T12, T8 (digits stripped)
    "chest": {"chest": 1.0}, "upperchest": {"chest": 1.0}, "spineupper": {"chest": 0.9},
    "thorax": {"chest": 1.0}, "ribcage": {"chest": 0.9}, "csbvh": {"chest": 0.6},
    "neck": {"neck": 1.0}, "shouldercenter": {"neck": 0.9}, "spineshoulder": {"neck": 0.9},
    "neckbase": {"neck": 1.0}, "necklower": {"neck": 1.0}, "neckupper": {"neck": 1.0},
    "lowerneck": {"neck": 1.0}, "upperneck": {"neck": 1.0},  # ASF/AMC
    "upperback": {"spine": 1.0}, "midback": {"spine": 0.9},
    "c": {"neck": 0.8},  # Xsens/anatomical C7
    "head": {"head": 1.0}, "skull": {"head": 0.9},
}
_SIDED: dict[str, dict[str, float]] = {
    "hipjoint": {"hipjoint": 1.0}, "buttock": {"hipjoint": 1.0},
    "hip": {"thigh": 1.0, "hipjoint": 0.5},
    "upleg": {"thigh": 1.0}, "upperleg": {"thigh": 1.0}, "thigh": {"thigh": 1.0},
    "femur": {"thigh": 1.0}, "legupper": {"thigh": 1.0},
    "leg": {"shin": 0.8, "thigh": 0.3}, "lowerleg": {"shin": 1.0}, "shin": {"shin": 1.0},
    "knee": {"shin": 1.0}, "calf": {"shin": 1.0}, "tibia": {"shin": 1.0},
    "leglower": {"shin": 1.0}, "crus": {"shin": 1.0},
    "foot": {"foot": 1.0, "toe": 0.5}, "ankle": {"foot": 1.0},
    "toebase": {"toe": 1.0}, "toe": {"toe": 1.0}, "toes": {"toe": 1.0}, "ball": {"toe": 0.9},
    "collar": {"clavicle": 1.0}, "clavicle": {"clavicle": 1.0}, "scapula": {"clavicle": 0.9},
    "shoulder": {"clavicle": 0.8, "upperarm": 0.6},
    "arm": {"upperarm": 0.8, "forearm": 0.2}, "upperarm": {"upperarm": 1.0},
    "shldr": {"upperarm": 0.9}, "humerus": {"upperarm": 1.0}, "armupper": {"upperarm": 1.0},
    "uarm": {"upperarm": 1.0}, "farm": {"forearm": 1.0},  # OptiTrack Motive LUArm, LFArm
    "uleg": {"thigh": 1.0},
    "forearm": {"forearm": 1.0}, "lowerarm": {"forearm": 1.0}, "elbow": {"forearm": 1.0},
    "armlower": {"forearm": 1.0}, "radius": {"forearm": 0.9},
    "hand": {"hand": 0.95}, "wrist": {"hand": 1.0}, "palm": {"hand": 0.9},
    "eye": {}, "ear": {}, "breast": {},
}


@dataclass(frozen=True)
class NameInfo:
    """What one joint name says.

    side: "L", "R" or None; parts: part -> score in (0, 1]; kind: "body", "finger", "end"
    (an end marker such as ``HeadTop_End``), "twist" (roll/twist helpers) or "other".
    """

    name: str
    tokens: tuple[str, ...]
    side: str | None
    base: str
    index: int | None  # trailing number (Spine2 -> 2), None if none
    kind: str
    parts: dict[str, float] = field(default_factory=dict)


def tokenize(name: str) -> list[str]:
    """Lower-case tokens: ``'mixamorig:LeftUpLeg'`` -> ``['left', 'up', 'leg']``."""
    if ":" in name:  # namespace (mixamorig:, Character1:, rig:)
        name = name.rsplit(":", 1)[1]
    raw = _TOKEN.findall(name)
    if raw and len(raw[0]) == 2 and raw[0][0] in "LR" and raw[0].isupper() and len(raw) > 1:
        raw = [raw[0][0], raw[0][1]] + raw[1:]  # OptiTrack Motive "LUArm" -> L U Arm
    toks = [t.lower() for t in raw]
    # drop tool prefixes and their numbers ("bip 01", "character 1")
    while len(toks) > 1 and (toks[0] in _PREFIX_TOKENS or toks[0].isdigit()):
        toks = toks[1:]
    return toks


def _unglue(word: str) -> tuple[str | None, str]:
    """('L'|'R'|None, rest) for a word with a glued side prefix or suffix whose rest is a
    known sided part (the longest side spelling first)."""
    for spell, side in (("left", "L"), ("right", "R"), ("l", "L"), ("r", "R")):
        if word.startswith(spell) and word[len(spell):] in _SIDED:
            return side, word[len(spell):]
        if len(spell) > 1 and word.endswith(spell) and word[:-len(spell)] in _SIDED:
            return side, word[:-len(spell)]
    return None, word


def classify(name: str) -> NameInfo:
    """Side, base name and part evidence of one joint name."""
    toks = tokenize(name)
    side = None
    core = list(toks)
    words = [t for t in core if not t.isdigit()]
    # a side token at either end, unless it is all that is left besides digits (Xsens L5)
    if len(words) > 1 and core and core[0] in _LEFT | _RIGHT:
        side = "L" if core[0] in _LEFT else "R"
        core = core[1:]
    elif len(words) > 1 and core and core[-1] in _LEFT | _RIGHT:
        side = "L" if core[-1] in _LEFT else "R"
        core = core[:-1]
    elif len(words) > 1 and len(core) > 1 and core[-2] in _LEFT | _RIGHT and core[-1].isdigit():
        side = "L" if core[-2] in _LEFT else "R"
        core = core[:-2] + core[-1:]
    if side is None and len(words) == 1 and core:
        # glued lower- or upper-case names: lfemur, rhumerus (ASF), leftupleg, HIPLEFT
        side, core[0] = _unglue(core[0])
    index = None
    while core and core[-1].isdigit():
        index = int(core[-1]) if index is None else index
        core = core[:-1]
    tokset = set(core)
    kind = "body"
    # "mid" is a finger only with a side (daz lMid1); Kinect's SpineMid is the spine
    if tokset & _FINGER or ("in" in tokset and "hand" in tokset) or \
            (side and "mid" in tokset):
        kind = "finger"
    elif tokset & _END and len(core) > 1:
        kind = "end"
    elif tokset & _TWIST and len(core) > 1:
        kind = "twist"
    base = "".join(core)
    parts: dict[str, float] = {}
    if kind == "body":
        table = _SIDED if side else _UNSIDED
        parts = dict(table.get(base, {}))
        if not parts and side is None:
            # sided names written without a side cannot be placed (e.g. "UpperArm")
            parts = {k: 0.5 * v for k, v in _SIDED.get(base, {}).items()}
        if not parts and index is not None and base in ("spine", "chest", "neck"):
            parts = dict(_UNSIDED[base])
        if not parts and len(core) > 1:
            # a modifier word around a known part (lThighBend, chestUpper, abdomenLower)
            for mod in _MODIFIERS:
                for cand in ("".join(t for t in core if t != mod),):
                    if mod in core and cand in table:
                        parts = {k: 0.9 * v for k, v in table[cand].items()}
                        break
                if parts:
                    break
        if not parts:
            kind = "other"
    return NameInfo(name=name, tokens=tuple(toks), side=side, base=base, index=index,
                    kind=kind, parts=parts)


# Target parts of the MakeHuman cmu_mb rig, per side where sided.
PART_BONES = {
    ("pelvis", None): "Hips", ("head", None): "Head",
    ("hipjoint", "L"): "LHipJoint", ("hipjoint", "R"): "RHipJoint",
    ("thigh", "L"): "LeftUpLeg", ("thigh", "R"): "RightUpLeg",
    ("shin", "L"): "LeftLeg", ("shin", "R"): "RightLeg",
    ("foot", "L"): "LeftFoot", ("foot", "R"): "RightFoot",
    ("toe", "L"): "LeftToeBase", ("toe", "R"): "RightToeBase",
    ("clavicle", "L"): "LeftShoulder", ("clavicle", "R"): "RightShoulder",
    ("upperarm", "L"): "LeftArm", ("upperarm", "R"): "RightArm",
    ("forearm", "L"): "LeftForeArm", ("forearm", "R"): "RightForeArm",
    ("hand", "L"): "LeftHand", ("hand", "R"): "RightHand",
}

# What a mapping must contain to be accepted, with the words used in refusals.
ESSENTIAL = {
    "Hips": "pelvis", "Head": "head",
    "LeftUpLeg": "left thigh", "RightUpLeg": "right thigh",
    "LeftLeg": "left shin", "RightLeg": "right shin",
    "LeftFoot": "left foot", "RightFoot": "right foot",
    "LeftArm": "left upper arm", "RightArm": "right upper arm",
    "LeftForeArm": "left forearm", "RightForeArm": "right forearm",
    "LeftHand": "left hand", "RightHand": "right hand",
}
