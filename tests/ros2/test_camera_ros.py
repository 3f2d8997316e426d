"""``--camera ros2:TOPIC`` end to end (DESIGN 11, 12): a real rclpy publisher of
``sensor_msgs/Image`` (bgr8 with padded rows) or ``CompressedImage`` (JPEG) in the test
process, the robot process on ``--driver ros2``, and an operator process whose saved view is
read back: the picture arrives, scaled into 320x240, with its colours the right way round."""

from __future__ import annotations

import io
import signal
import threading

import numpy as np
import pytest

pytest.importorskip("rclpy", reason="ROS 2's rclpy is not installed (pip install -e '.[ros2]')")

import rclpy
from egc_common.transport import free_tcp_port, loopback_endpoint
from egc_operator import view_blueprint as paths
from PIL import Image
from rclpy.context import Context
from rclpy.qos import qos_profile_sensor_data
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import CompressedImage
from sensor_msgs.msg import Image as ImageMsg

from tests.integration.harness import ROBOT, Processes
from tests.ros2.fake_base import STOP_PATIENCE_S, FakeBase
from tests.ros2.test_robot_ros import wait_log
from tests.view.rrd import read_recording

pytestmark = [pytest.mark.integration, pytest.mark.timeout(180)]

WIDTH, HEIGHT = 640, 480
RED, BLUE = (220, 30, 30), (30, 40, 220)


@pytest.fixture
def procs(tmp_path):
    group = Processes(tmp_path)
    try:
        yield group
    finally:
        group.cleanup()
        for name in group.children:  # shown by pytest when the test fails
            print(f"---- {name} ----\n{group.log(name)[-3000:]}")


def picture() -> np.ndarray:
    """Left half red, right half blue, RGB."""
    rgb = np.empty((HEIGHT, WIDTH, 3), np.uint8)
    rgb[:, : WIDTH // 2] = RED
    rgb[:, WIDTH // 2 :] = BLUE
    return rgb


class ImagePublisher:
    """A camera node: publishes ``kind`` ("image" or "compressed") at 10 Hz."""

    def __init__(self, kind: str, topic: str) -> None:
        self._context = Context()
        rclpy.init(context=self._context, signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node("fake_camera", context=self._context)
        cls = ImageMsg if kind == "image" else CompressedImage
        self._pub = self.node.create_publisher(cls, topic, qos_profile_sensor_data)
        rgb = picture()
        if kind == "image":
            msg = ImageMsg()
            msg.height, msg.width, msg.encoding, msg.is_bigendian = HEIGHT, WIDTH, "bgr8", 0
            pad = 64  # a driver that aligns rows
            msg.step = WIDTH * 3 + pad
            rows = np.concatenate(
                [rgb[:, :, ::-1].reshape(HEIGHT, -1), np.full((HEIGHT, pad), 0xEE, np.uint8)],
                axis=1,
            )
            msg.data = rows.tobytes()
        else:
            msg = CompressedImage()
            msg.format = "jpeg"
            buffer = io.BytesIO()
            Image.fromarray(rgb).save(buffer, format="JPEG", quality=90)
            msg.data = buffer.getvalue()
        msg.header.frame_id = "camera"
        self._msg = msg
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True)
        self._thread.start()

    def _loop(self) -> None:
        while not self._stop.wait(0.1):
            self._msg.header.stamp = self.node.get_clock().now().to_msg()
            self._pub.publish(self._msg)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(STOP_PATIENCE_S)
        if self._thread.is_alive():  # never destroy the node under its thread (issue 31)
            raise AssertionError(f"the camera's thread did not stop in {STOP_PATIENCE_S} s")
        self.node.destroy_node()
        self._context.try_shutdown()


@pytest.mark.parametrize(
    "kind,topic", [("image", "/camera/image_raw"), ("compressed", "/camera/image_raw/compressed")]
)
def test_a_ros2_image_topic_reaches_the_operator_view(ros_domain, procs, tmp_path, kind, topic):
    base = FakeBase()
    camera = ImagePublisher(kind, topic)
    try:
        port = free_tcp_port()
        procs.start(
            "robot",
            "robot",
            "--robot",
            ROBOT,
            "--driver",
            "ros2",
            "--camera",
            f"ros2:{topic}",
            "--listen",
            loopback_endpoint(port),
        )
        wait_log(procs, "robot", r"ready: driver ros2")
        wait_log(procs, "robot", rf"camera: {topic} \(sensor_msgs/msg/", 30.0)
        save = tmp_path / "operator.rrd"
        operator = procs.start(
            "operator",
            "operator",
            "--robot",
            ROBOT,
            "--script",
            "demo",
            "--duration",
            "5",
            "--no-status",
            "--save",
            str(save),
            "--zenoh-connect",
            loopback_endpoint(port),
        )
        operator.wait(60)
        assert operator.returncode == 0
        assert procs.stop("robot", signal.SIGINT) == 0
    finally:
        camera.close()
        base.close()
    rec = read_recording(save)
    blobs = [b for b in rec[f"/{paths.CAMERA_IMAGE}"].column("EncodedImage:blob") if b]
    assert len(blobs) >= 5, procs.log("robot")[-2000:]
    shown = Image.open(io.BytesIO(bytes(blobs[-1][0])))
    assert shown.size == (320, 240)  # fitted into --camera-size
    rgb = np.asarray(shown.convert("RGB")).astype(int)
    left, right = rgb[:, 20:140].reshape(-1, 3).mean(0), rgb[:, 180:300].reshape(-1, 3).mean(0)
    assert np.allclose(left, RED, atol=25), left  # not swapped: bgr8 read as BGR
    assert np.allclose(right, BLUE, atol=25), right
