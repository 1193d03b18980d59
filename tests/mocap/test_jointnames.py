import pytest

from vhgen.mocap.jointnames import classify


def _best(name):
    i = classify(name)
    part = max(i.parts, key=lambda k: i.parts[k]) if i.parts else i.kind
    return i.side, part


@pytest.mark.parametrize("name, side, part", [
    ("LeftUpLeg", "L", "thigh"), ("mixamorig:RightForeArm", "R", "forearm"),
    ("Bip01 L Thigh", "L", "thigh"), ("Bip01 R Calf", "R", "shin"),
    ("Bip01 L UpperArm", "L", "upperarm"), ("Bip01 Pelvis", None, "pelvis"),
    ("Bip01 HeadNub", None, "end"), ("Bip01 L Finger0", "L", "finger"),
    ("RightUpperLeg", "R", "thigh"), ("L5", None, "spine"), ("T8", None, "spine"),
    ("UpperLeg_L", "L", "thigh"), ("LowerArm_R", "R", "forearm"), ("thigh.L", "L", "thigh"),
    ("DEF-upper_arm.L.001", "L", "upperarm"), ("HipLeft", "L", "thigh"),
    ("ElbowRight", "R", "forearm"), ("ShoulderCenter", None, "neck"),
    ("SpineMid", None, "spine"), ("LeftHip", "L", "thigh"), ("lThigh", "L", "thigh"),
    ("rShldr", "R", "upperarm"), ("lButtock", "L", "hipjoint"), ("LHipJoint", "L", "hipjoint"),
    ("lThighBend", "L", "thigh"), ("lThighTwist", "L", "twist"), ("chestUpper", None, "chest"),
    ("abdomenLower", None, "spine"), ("LUArm", "L", "upperarm"), ("LFArm", "L", "forearm"),
    ("LThigh", "L", "thigh"), ("lfemur", "L", "thigh"), ("rhumerus", "R", "upperarm"),
    ("lowerback", None, "spine"), ("upperneck", None, "neck"), ("ltibia", "L", "shin"),
    ("LeftForeArmRoll", "L", "twist"), ("HeadTop_End", None, "end"),
    ("LeftInHandIndex", "L", "finger"), ("lMid1", "L", "finger"), ("leftEye", "L", "other"),
    ("Character1_LeftHand", "L", "hand"), ("WristLeft", "L", "hand"),
    ("leftcollar", "L", "clavicle"), ("LEFTUPLEG", "L", "thigh"), ("hipright", "R", "thigh"),
    ("L_THIGH", "L", "thigh"), ("rtoes", "R", "toe"), ("lowerback", None, "spine"),
    ("Root", None, "other"), ("rib", None, "other"), ("leg", None, "shin"),
])
def test_names_across_conventions(name, side, part):
    assert _best(name) == (side, part)
