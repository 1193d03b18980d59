"""Motion capture: BVH parsing, forward kinematics, retargeting onto the MakeHuman rig."""

from vhgen.mocap.bvh import Motion, forward_kinematics, parse_bvh, read_bvh

__all__ = ["Motion", "forward_kinematics", "parse_bvh", "read_bvh"]
