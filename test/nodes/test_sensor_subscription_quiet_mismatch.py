"""A best-effort camera next to the cell's dual reader logs no "incompatible QoS" warning (CI log, 2026-11-29).

Until the publishers are known, qos.SensorSubscription reads with a best-effort and a reliable reader; the
reliable one cannot match a best-effort camera, and rclpy's default event handler then warned "New publisher
discovered ..., offering incompatible QoS. No messages will be received from it" from every perceiving node,
while the frames arrived through the other reader. The reader handles the event itself (debug log). The
camera's side ("requesting incompatible QoS") is logged by the camera driver's process and stays."""
import pytest

pytestmark = pytest.mark.ros

TOPIC = "quiet_camera/depth/image_rect_raw"


def test_a_best_effort_camera_is_read_without_an_incompatible_qos_warning(executor, spin, capfd):
    from rclpy.node import Node
    from sensor_msgs.msg import Image

    from defgg_ros.ros import qos

    node = Node("quiet_camera_reader", context=executor.context)
    camera = Node("quiet_camera", context=executor.context)
    executor.add_node(node)
    executor.add_node(camera)
    stamps = []
    reader = qos.SensorSubscription(node, Image, TOPIC, lambda m: stamps.append(m.header.stamp.sec),
                                    warn_after_s=0.0)
    publisher = camera.create_publisher(Image, TOPIC, qos.SENSOR_DATA)   # best effort, as some drivers offer

    def publish():
        frame = Image(height=2, width=2, encoding="16UC1", step=4, data=bytes(8))
        frame.header.stamp.sec = len(stamps) + 1
        publisher.publish(frame)

    timer = camera.create_timer(0.05, publish)
    spin(executor, lambda: len(stamps) >= 5 and not reader.undecided, 20.0, "frames through the best-effort reader")
    camera.destroy_timer(timer)
    assert reader.reliability.name == "BEST_EFFORT"
    err = capfd.readouterr().err   # the camera's own "requesting incompatible QoS" is its driver's, not ours
    assert "offering incompatible QoS" not in err, err
    assert reader.incompatible_events >= 1   # the mismatch did happen: it was handled, not absent
