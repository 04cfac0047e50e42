"""A recording plays one period at a time; new message fields are checked where made."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from acslam.config import load_algorithms
from acslam.errors import ConfigError, MessageError
from acslam.messages import LandmarkObservations, OdometryIncrement, RobotSighting
from acslam.replay import preset
from acslam.sources.recorded import RecordedSource


def _odometry(stamp: float) -> OdometryIncrement:
    return OdometryIncrement(0, stamp, max(stamp - 0.05, 0.0), 0.01, 0.0, 0.0)


def _batches(source: RecordedSource) -> list[list[float]]:
    batches = []
    while not source.finished:
        batches.append([m.stamp for m in source.receive()])
        source.advance()
    return batches


def test_messages_play_as_the_server_receives_them() -> None:
    """The step at T gets what was stamped in (T - period, T], T from the first stamp."""
    stamps = [0.25, 0.0, 0.1, 0.05, 0.3]  # out of order on purpose: the source sorts
    source = RecordedSource([_odometry(t) for t in stamps], period_s=0.1)
    assert _batches(source) == [[0.0], [0.05, 0.1], [], [0.25, 0.3]]
    assert source.time_s == pytest.approx(0.4)
    assert source.newly_lost() == []


def test_steps_count_from_the_recordings_start_and_tolerate_ns_rounding() -> None:
    """A stamp a few ns past a step (a ROS stamp rounded to ns) is on time; one a
    microsecond late waits for the next step. Steps are start + k period, never a sum."""
    stamps = [1.3 + 2e-9, 1.3 + 1e-6, 101.0]
    source = RecordedSource([_odometry(t) for t in stamps], period_s=0.1, start_s=1.0)
    batches = _batches(source)
    assert batches[:4] == [[], [], [], [1.3 + 2e-9]]
    assert batches[4] == [1.3 + 1e-6]
    assert batches[-1] == [101.0] and len(batches) == 1001


def test_equal_stamps_keep_their_order() -> None:
    first, second = _odometry(1.0), LandmarkObservations(0, 1.0, np.zeros((1, 3)))
    source = RecordedSource([first, second], period_s=1.0)
    assert source.receive() == [first, second]


@pytest.mark.parametrize(
    ("make", "field"),
    [
        (lambda: RobotSighting(1, 0.0, 1, np.zeros(3)), "observed_id"),
        (lambda: RobotSighting(1, 0.0, 2, np.array([np.nan, 0.0, 0.0])), "point"),
        (lambda: LandmarkObservations(0, 0.0, np.zeros((2, 3)), ids=np.array([4])), "ids"),
        (lambda: LandmarkObservations(0, 0.0, np.zeros((1, 3)), ids=np.array([0.5])), "ids"),
    ],
)
def test_bad_new_message_fields_are_rejected_where_made(make, field: str) -> None:
    with pytest.raises(MessageError, match=field):
        make()


def test_presets_load_and_a_bad_algorithms_file_names_its_field(tmp_path: Path) -> None:
    carmen = preset("carmen")
    assert carmen.scan_matching.submap_keyframes == 5
    assert carmen.localizer.isam_factorization == "QR"
    assert preset("mrclam").planning.control_period_s == 1.0
    bad = tmp_path / "mine.yaml"
    bad.write_text("mapper: {name: log-odds, max_range_m: -1}\n")
    with pytest.raises(ConfigError) as info:
        load_algorithms(bad)
    assert (info.value.source, info.value.field) == (str(bad), "algorithms.mapper.max_range_m")
