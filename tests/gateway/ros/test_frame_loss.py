"""Frames lost on the way told apart from frames replaced while the route was busy (no ROS;
the real camera cases are in test_foreign_camera.py)."""

from __future__ import annotations

from oricf.gateway.ros.frame_loss import MIN_LOST, FrameLoss, camera_side_fix, replaceable


def test_a_gap_in_front_of_a_frame_the_receiver_waited_for_is_all_lost() -> None:
    assert replaceable(gap=3, waited=True, busy_s=10.0, span_s=0.4) == 0


def test_a_busy_route_explains_as_many_frames_as_arrive_while_it_works() -> None:
    # Frames 100 ms apart: a route busy for 250 ms can have 3 replaced (half a frame of
    # leeway), not the 5 that were missing in front of this one.
    assert replaceable(gap=5, waited=False, busy_s=0.25, span_s=0.6) == 3
    assert replaceable(gap=1, waited=False, busy_s=0.25, span_s=0.2) == 1
    # A route far quicker than the camera replaces nothing: a gap is a loss.
    assert replaceable(gap=2, waited=False, busy_s=0.01, span_s=0.3) == 0


def test_without_the_publishers_pace_every_missing_frame_may_have_been_replaced() -> None:
    assert replaceable(gap=4, waited=False, busy_s=0.05, span_s=0.0) == 4
    assert replaceable(gap=4, waited=False, busy_s=0.05, span_s=-1.0) == 4  # a restarted clock


def test_losses_call_for_a_warning_once_they_are_many_and_a_tenth_of_the_frames() -> None:
    loss = FrameLoss()
    assert loss.add(gap=2, replaceable=2) == 2  # replaced: not a loss
    for _ in range(MIN_LOST - 1):
        assert loss.add(gap=1, replaceable=0) == 0
        assert not loss.warning_due
    loss.add(gap=1, replaceable=0)
    assert (loss.published, loss.lost) == (3 + 2 * MIN_LOST, MIN_LOST)
    assert loss.warning_due
    loss.warned = True
    assert not loss.warning_due


def test_a_few_frames_lost_among_many_are_not_worth_a_warning() -> None:
    loss = FrameLoss()
    for i in range(200):
        loss.add(gap=1 if i % 20 == 0 else 0, replaceable=0)
    assert loss.lost == 10 and not loss.warning_due


def test_counting_again_keeps_a_warning_given() -> None:
    loss = FrameLoss(published=40, lost=30, warned=True)
    loss.restart()
    assert (loss.published, loss.lost, loss.warned) == (0, 0, True)


def test_the_fix_names_large_data_sizes_above_the_frame() -> None:
    assert "LARGE_DATA?max_msg_size=1MB&sockets_size=1MB" in camera_side_fix(921_660)
    assert "LARGE_DATA?max_msg_size=3MB&sockets_size=3MB" in camera_side_fix(1280 * 720 * 3)
    assert "python -m oricf.gateway.ros.dds" in camera_side_fix(100)
