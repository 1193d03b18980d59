"""Write vhgen's built-in demo motion, ``vhgen/data/demo_cmu_mb.bvh``.

A procedural 8-second clip on a skeleton with the CMU MotionBuilder-friendly joint names
and round-number adult proportions of our own (CMU units, 0.056444 m), zero rotations =
T-pose. Segments: walk in place, wave, squat with arms forward, torso twist and lean,
with a slow turn of the whole body. Deterministic; rerun to regenerate.

    python scripts/make_demo_motion.py
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from vhgen.rotations import axis_rotation, matrix_to_euler

FPS = 30
# (name, parent, offset); End Sites as (None, parent, offset)
SKELETON = [
    ("Hips", None, (0, 0, 0)),
    ("LHipJoint", "Hips", (0, 0, 0)), ("LeftUpLeg", "LHipJoint", (1.6, -1.5, 0.3)),
    ("LeftLeg", "LeftUpLeg", (0, -7.4, 0)), ("LeftFoot", "LeftLeg", (0, -7.2, 0)),
    ("LeftToeBase", "LeftFoot", (0, -0.9, 2.3)), (None, "LeftToeBase", (0, 0, 1.1)),
    ("RHipJoint", "Hips", (0, 0, 0)), ("RightUpLeg", "RHipJoint", (-1.6, -1.5, 0.3)),
    ("RightLeg", "RightUpLeg", (0, -7.4, 0)), ("RightFoot", "RightLeg", (0, -7.2, 0)),
    ("RightToeBase", "RightFoot", (0, -0.9, 2.3)), (None, "RightToeBase", (0, 0, 1.1)),
    ("LowerBack", "Hips", (0, 0, 0)), ("Spine", "LowerBack", (0, 2.0, -0.1)),
    ("Spine1", "Spine", (0, 2.0, 0)), ("Neck", "Spine1", (0, 0, 0)),
    ("Neck1", "Neck", (0, 1.7, 0.1)), ("Head", "Neck1", (0, 1.7, 0)), (None, "Head", (0, 2.0, 0)),
    ("LeftShoulder", "Spine1", (0, 0, 0)), ("LeftArm", "LeftShoulder", (3.3, 1.1, -0.2)),
    ("LeftForeArm", "LeftArm", (5.0, 0, 0)), ("LeftHand", "LeftForeArm", (3.6, 0, 0)),
    ("LeftFingerBase", "LeftHand", (0, 0, 0)), ("LeftHandIndex1", "LeftFingerBase", (0.8, 0, 0)),
    (None, "LeftHandIndex1", (0.7, 0, 0)), ("LThumb", "LeftHand", (0, 0, 0)),
    (None, "LThumb", (0.5, 0, 0.6)),
    ("RightShoulder", "Spine1", (0, 0, 0)), ("RightArm", "RightShoulder", (-3.3, 1.1, -0.2)),
    ("RightForeArm", "RightArm", (-5.0, 0, 0)), ("RightHand", "RightForeArm", (-3.6, 0, 0)),
    ("RightFingerBase", "RightHand", (0, 0, 0)),
    ("RightHandIndex1", "RightFingerBase", (-0.8, 0, 0)), (None, "RightHandIndex1", (-0.7, 0, 0)),
    ("RThumb", "RightHand", (0, 0, 0)), (None, "RThumb", (-0.5, 0, 0.6)),
]
HIP_HEIGHT = 1.5 + 7.4 + 7.2 + 0.9  # root above the floor at rest

ARMS_DOWN = {"LeftArm": [("Z", -72)], "RightArm": [("Z", 72)],
             "LeftForeArm": [("Y", -10)], "RightForeArm": [("Y", 10)]}


def _walk(phase: float) -> dict:
    s = np.sin(2 * np.pi * phase)
    pose = {"LeftUpLeg": [("X", -28 * s)], "RightUpLeg": [("X", 28 * s)],
            "LeftLeg": [("X", 35 * max(0.0, s))], "RightLeg": [("X", 35 * max(0.0, -s))],
            "LeftArm": [("Z", -72), ("X", 25 * s)], "RightArm": [("Z", 72), ("X", -25 * s)],
            "LeftForeArm": [("Y", -25)], "RightForeArm": [("Y", 25)],
            "Spine1": [("Y", 6 * s)]}
    return pose


def _keyframes(t: float) -> tuple[dict, float, float]:
    """Pose (joint -> [(axis, deg)]), root drop in units, body yaw in degrees at time t."""
    yaw = 40.0 * np.sin(2 * np.pi * t / 8.0)
    if t < 2.0:
        return _walk(t / 1.0), 0.3 * abs(np.sin(2 * np.pi * t)), yaw
    if t < 4.0:  # wave with the right arm, left arm on the hip
        w = np.sin(2 * np.pi * (t - 2.0) * 1.5)
        pose = {"RightArm": [("Z", -60)], "RightForeArm": [("Z", -60 + 25 * w)],
                "LeftArm": [("Z", -60), ("Y", 30)], "LeftForeArm": [("Y", -100)],
                "Neck1": [("Y", -15)], "Head": [("X", 10)]}
        return pose, 0.0, yaw
    if t < 6.0:  # squat with the arms forward
        a = 0.5 - 0.5 * np.cos(2 * np.pi * (t - 4.0) / 2.0)
        pose = {"LeftUpLeg": [("X", -95 * a)], "RightUpLeg": [("X", -95 * a)],
                "LeftLeg": [("X", 110 * a)], "RightLeg": [("X", 110 * a)],
                "LeftFoot": [("X", -20 * a)], "RightFoot": [("X", -20 * a)],
                "LowerBack": [("X", 25 * a)],
                "LeftArm": [("Z", -72 * (1 - a)), ("Y", -85 * a)],
                "RightArm": [("Z", 72 * (1 - a)), ("Y", 85 * a)]}
        return pose, 6.5 * a, yaw
    a = np.sin(2 * np.pi * (t - 6.0) / 2.0)  # twist and side lean, arms out
    pose = {"LowerBack": [("Y", 35 * a)], "Spine": [("Z", 15 * a)], "Spine1": [("Y", 20 * a)],
            "LeftArm": [("Z", -20)], "RightArm": [("Z", 20)],
            "LeftForeArm": [("Y", -40 * max(0, a))], "RightForeArm": [("Y", 40 * max(0, -a))],
            "Head": [("Y", -30 * a)]}
    return pose, 0.0, yaw


def _blend(p0: dict, p1: dict, w: float) -> dict:
    out = {}
    for j in set(p0) | set(p1):
        out[j] = [(ax, (1 - w) * d) for ax, d in p0.get(j, [])] + \
                 [(ax, w * d) for ax, d in p1.get(j, [])]
    return out


def build_frames(duration: float = 8.0) -> np.ndarray:
    joints = [n for n, _, _ in SKELETON if n]
    rows = []
    for i in range(int(duration * FPS)):
        t = i / FPS
        pose, drop, yaw = _keyframes(t)
        # cross-fade 0.25 s into each segment so the clip has no jumps
        seg_start = np.floor(t / 2.0) * 2.0
        if seg_start > 0 and t - seg_start < 0.25:
            prev, pdrop, _ = _keyframes(seg_start - 1e-6)
            w = (t - seg_start) / 0.25
            w = w * w * (3 - 2 * w)
            pose = _blend(prev, pose, w)
            drop = (1 - w) * pdrop + w * drop
        row = [0.0, HIP_HEIGHT - drop, 0.0]
        for j in joints:
            r = np.eye(3)
            if j == "Hips":
                r = axis_rotation("Y", np.deg2rad(yaw))
            for ax, deg in pose.get(j, []):
                r = r @ axis_rotation(ax, np.deg2rad(deg))
            row.extend(np.rad2deg(matrix_to_euler(r, "ZYX")))
        rows.append(row)
    return np.asarray(rows)


def write_bvh(path: Path) -> None:
    lines = ["HIERARCHY"]
    depth = {None: -1}
    open_stack: list[str | None] = []

    def close_to(level: int) -> None:
        while len(open_stack) > level:
            open_stack.pop()
            lines.append("\t" * len(open_stack) + "}")

    for name, parent, off in SKELETON:
        level = depth[parent] + 1
        close_to(level)
        ind = "\t" * level
        if name is None:
            lines += [f"{ind}End Site", f"{ind}{{", f"{ind}\tOFFSET {off[0]:.4f} {off[1]:.4f} "
                      f"{off[2]:.4f}"]
            open_stack.append(None)
            continue
        kw = "ROOT" if parent is None else "JOINT"
        chans = ("CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation"
                 if parent is None else "CHANNELS 3 Zrotation Yrotation Xrotation")
        lines += [f"{ind}{kw} {name}", f"{ind}{{",
                  f"{ind}\tOFFSET {off[0]:.4f} {off[1]:.4f} {off[2]:.4f}", f"{ind}\t{chans}"]
        open_stack.append(name)
        depth[name] = level
    close_to(0)
    frames = build_frames()
    lines += ["MOTION", f"Frames: {len(frames)}", f"Frame Time: {1 / FPS:.6f}"]
    lines += [" ".join(f"{v:.4f}" for v in row) for row in frames]
    path.write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    out = Path(__file__).resolve().parent.parent / "vhgen" / "data" / "demo_cmu_mb.bvh"
    write_bvh(out)
    print(f"wrote {out}")
