"""End to end over real DDS: vtest.avi frames on camera/image_raw -> /human_counter."""

from __future__ import annotations

import time

from rclpy.context import Context

from oricf.gateway.values import Frame
from oricf.v1 import detector_pb2, detector_pb2_grpc
from tests.gateway.pipelines import people_qa
from tests.gateway.ros.gateway_node import running_gateway
from tests.support.data import video_frames
from tests.support.detections import count
from tests.support.processes import free_port, oricf_process, wait_serving
from tests.support.services import RunningService

FRAMES = [0, 80, 160, 400, 440, 560]


def test_vtest_frames_give_plausible_counts(ros_context: Context,
                                            detector: RunningService) -> None:
    frames = video_frames(FRAMES)
    with running_gateway(people_qa(detector=detector.address), ros_context) as (gw, probe):
        counts, annotated = [], []
        for i, frame in enumerate(frames):
            probe.publish_frame(frame, frame_id="front_camera", stamp_s=1000 + i)
            counts.append(probe.next("/human_counter", timeout=10).data)
            annotated.append(probe.next("/camera/image_annotated", timeout=10))
        stub = detector_pb2_grpc.DetectorStub(detector.channel)
        direct = [count(stub.Detect(detector_pb2.DetectRequest(
            image=Frame.from_pixels(f).to_proto(), labels=["person"]), timeout=10))
            for f in frames]
    # vtest.avi: a street with a handful of pedestrians; YOLOX-Nano finds 4-9 per frame.
    assert all(3 <= count <= 12 for count in counts), counts
    assert counts == direct  # the gateway passes frames on unchanged and counts every person
    assert [a.header.stamp.sec for a in annotated] == [1000 + i for i in range(len(frames))]
    last = annotated[-1]  # stamped and framed like its input, so it can be matched to it
    assert last.header.frame_id == "front_camera"
    assert (last.width, last.height, last.encoding) == (768, 576, "bgr8")
    assert len(last.data) == 768 * 576 * 3
    assert gw.pipeline.products.read("people_count").value == counts[-1]


def test_rgb8_and_mono8_frames_are_counted(ros_context: Context,
                                           detector: RunningService) -> None:
    import cv2

    frame = video_frames([0])[0]
    with running_gateway(people_qa(detector=detector.address), ros_context) as (_, probe):
        probe.publish_frame(cv2.cvtColor(frame, cv2.COLOR_BGR2RGB), "rgb8")
        rgb = probe.next("/human_counter", timeout=10).data
        probe.publish_frame(cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY), "mono8")
        mono = probe.next("/human_counter", timeout=10).data
    assert rgb == 4  # frame 0: three pedestrians and a post the model takes for one
    assert 2 <= mono <= 6


def test_compressed_images_are_counted(ros_context: Context, detector: RunningService) -> None:
    from sensor_msgs.msg import CompressedImage

    from oricf.imaging import encode_image

    compressed = {"routes": {"people": {"input": {"topic": "camera/compressed",
                                                  "type": "sensor_msgs/CompressedImage"}}}}
    frame = video_frames([0])[0]
    config = people_qa(compressed, detector=detector.address)
    with running_gateway(config, ros_context) as (_, probe):
        for fmt, encoding in (("jpeg", "jpeg"), ("bgr8; png compressed bgr8", "png")):
            msg = CompressedImage(format=fmt)
            msg.data = encode_image(frame, encoding)
            probe.compressed.publish(msg)
            assert probe.next("/human_counter", timeout=10).data == 4
        annotated = probe.next("/camera/image_annotated", timeout=10)
    assert (annotated.width, annotated.height) == (768, 576)


def test_a_burst_of_frames_keeps_only_the_newest(ros_context: Context) -> None:
    frames = video_frames([0, 80])  # 4 and 7 people found
    # The detector runs in its own process, as deployed: inside this one it would compete for
    # the interpreter with the burst of publishes below and now and then miss its deadline.
    address = f"127.0.0.1:{free_port()}"
    with oricf_process("serve", "detector", "--listen", address) as detector:
        wait_serving(address, timeout=120, process=detector)
        with running_gateway(people_qa(detector=address), ros_context) as (gw, probe):
            for _ in range(30):  # faster than the detector: frames arrive while it is busy
                probe.publish_frame(frames[0])
                time.sleep(0.005)
            probe.publish_frame(frames[1])
            time.sleep(1.0)  # every frame delivered
            assert gw.pipeline.idle(10)
            time.sleep(0.5)  # every count delivered
            counts = probe.drain("/human_counter")
            stats = gw.pipeline.workers["people"].stats
    assert 1 <= len(counts) < 31
    assert stats.dropped >= 1 and stats.handled == len(counts)
    # the last frame published is the last one counted: never an old frame after a new one
    assert counts[-1].data == 7 and stats.received == stats.dropped + stats.handled
