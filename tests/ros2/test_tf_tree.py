"""Static transforms: the laser mount through a chain of frames."""

from __future__ import annotations

import numpy as np

from acslam.geometry import compose
from acslam.ros2.tf_tree import TfTree


def test_the_mount_composes_a_chain_and_needs_a_common_root() -> None:
    tree = TfTree()
    # TurtleBot3: base_footprint -> base_link (up 1 cm) -> base_scan (3.2 cm back).
    tree.add("base_footprint", "base_link", np.zeros(3))
    tree.add("base_link", "base_scan", np.array([-0.032, 0.0, 0.0]))
    np.testing.assert_allclose(tree.lookup("base_footprint", "base_scan"), [-0.032, 0.0, 0.0])
    np.testing.assert_allclose(tree.lookup("base_scan", "base_footprint"), [0.032, 0.0, 0.0])
    # A turned laser on an arm: the chain composes in order.
    tree.add("base_link", "arm", np.array([0.1, 0.0, np.pi / 2]))
    tree.add("arm", "laser", np.array([0.2, 0.0, 0.0]))
    expected = compose(np.array([0.1, 0.0, np.pi / 2]), np.array([0.2, 0.0, 0.0]))
    np.testing.assert_allclose(tree.lookup("base_footprint", "laser"), expected, atol=1e-12)
    assert tree.lookup("base_footprint", "camera") is None  # not in the tree
    tree.add("other_robot/base_link", "other_robot/base_scan", np.zeros(3))
    assert tree.lookup("base_footprint", "other_robot/base_scan") is None
    np.testing.assert_array_equal(tree.lookup("x", "x"), np.zeros(3))
