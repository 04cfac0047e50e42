"""The one key scheme of the SLAM graph: every variable key is built and decoded here.

Keys are ``gtsam.symbol`` values: a character and a 56-bit index. Poses use ``'x'`` with
the index packing ``robot_id << 40 | keyframe_index`` (16 bits of robot id, so up to 65536
robots instead of the 26 a letter per robot would allow; 2^40 keyframes per robot);
landmarks, shared by all robots, use ``'l'`` with the landmark index. A key prints as e.g.
``x1099511627779`` in GTSAM's own output; :func:`describe` turns it back into words.
"""

from __future__ import annotations

import gtsam

POSE_CHAR = "x"
LANDMARK_CHAR = "l"
ROBOT_BITS = 16
INDEX_BITS = 40
MAX_ROBOTS = 1 << ROBOT_BITS
MAX_INDEX = 1 << INDEX_BITS


def pose_key(robot_id: int, index: int) -> int:
    """Key of keyframe ``index`` of robot ``robot_id``."""
    if not 0 <= robot_id < MAX_ROBOTS:
        raise ValueError(f"robot_id must be in [0, {MAX_ROBOTS}), got {robot_id}")
    if not 0 <= index < MAX_INDEX:
        raise ValueError(f"keyframe index must be in [0, {MAX_INDEX}), got {index}")
    return gtsam.symbol(POSE_CHAR, (robot_id << INDEX_BITS) | index)


def landmark_key(index: int) -> int:
    """Key of landmark ``index``."""
    if index < 0:
        raise ValueError(f"landmark index must be >= 0, got {index}")
    return gtsam.symbol(LANDMARK_CHAR, index)


def is_pose_key(key: int) -> bool:
    return chr(gtsam.Symbol(key).chr()) == POSE_CHAR


def decode_pose_key(key: int) -> tuple[int, int]:
    """``(robot_id, keyframe_index)`` of a pose key."""
    symbol = gtsam.Symbol(key)
    if chr(symbol.chr()) != POSE_CHAR:
        raise ValueError(f"not a pose key: {describe(key)}")
    packed = symbol.index()
    return packed >> INDEX_BITS, packed & (MAX_INDEX - 1)


def decode_landmark_key(key: int) -> int:
    symbol = gtsam.Symbol(key)
    if chr(symbol.chr()) != LANDMARK_CHAR:
        raise ValueError(f"not a landmark key: {describe(key)}")
    return symbol.index()


def describe(key: int) -> str:
    """Readable name of a key, for error messages: ``robot 2 keyframe 7`` / ``landmark 3``."""
    symbol = gtsam.Symbol(key)
    char = chr(symbol.chr())
    if char == POSE_CHAR:
        robot, index = decode_pose_key(key)
        return f"robot {robot} keyframe {index}"
    if char == LANDMARK_CHAR:
        return f"landmark {symbol.index()}"
    return f"key {key}"
