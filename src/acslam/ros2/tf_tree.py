"""Static transforms (``tf_static``) as a tree of frames, projected onto the plane.

The server needs one static transform per robot: the laser's mount in the base frame the
odometry reports (TurtleBot3: ``base_footprint -> base_link -> base_scan``). A chain of
any length is composed; height, roll and pitch are dropped (a planar robot with an
upright laser).
"""

from __future__ import annotations

import numpy as np

from acslam.geometry import between, compose


class TfTree:
    """Parent and planar pose of each child frame, as the latest static transforms say."""

    def __init__(self) -> None:
        self._parents: dict[str, tuple[str, np.ndarray]] = {}

    def add(self, parent: str, child: str, pose_xytheta: np.ndarray) -> None:
        self._parents[child] = (parent, np.asarray(pose_xytheta, dtype=float))

    def _to_root(self, frame: str) -> tuple[str, np.ndarray]:
        """The root of ``frame``'s tree and ``frame``'s pose in it."""
        pose = np.zeros(3)
        seen = {frame}
        while frame in self._parents:
            parent, relative = self._parents[frame]
            pose = compose(relative, pose)
            frame = parent
            if frame in seen:  # a cycle: the tree is corrupt
                break
            seen.add(frame)
        return frame, pose

    def lookup(self, target: str, source: str) -> np.ndarray | None:
        """The pose of frame ``source`` in frame ``target`` (``[x, y, theta]``), or None
        if no chain of static transforms joins them."""
        if target == source:
            return np.zeros(3)
        root_t, pose_t = self._to_root(target)
        root_s, pose_s = self._to_root(source)
        if root_t != root_s:
            return None
        return between(pose_t, pose_s)
