# Copyright 2026 The mlofc_ros Authors
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.
"""Shared DDS test harness: a test node and an executor spinning in a thread (real rclpy)."""
import os
from pathlib import Path
import sys
import threading
import time
from typing import Callable, Dict, List

from ament_index_python.packages import get_package_prefix, PackageNotFoundError
from mlofc_ros.image.decode import gray_to_image_fields
from mlofc_ros.ros_messages import stamp_to_seconds
import numpy as np
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.srv import GetParameters, SetParameters
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_sensor_data, QoSProfile
from sensor_msgs.msg import CameraInfo, Image

FRAME_ID = 'camera_optical_frame'
PACKAGE = 'mlofc_ros'


def executable(name: str) -> str:
    """
    Return the path of the package's executable ``name``, found as ``ros2 run`` finds it.

    First ``lib/mlofc_ros/<name>`` under the package's prefix in the ament index (a colcon
    workspace, or any install with the index marker on ``AMENT_PREFIX_PATH``), then the
    ``bin/`` of the Python running the tests (a pip install). Fails, never skips, when neither
    holds it: every test that starts the node or a bag tool goes through here.
    """
    candidates = []
    try:
        candidates.append(Path(get_package_prefix(PACKAGE)) / 'lib' / PACKAGE / name)
    except (PackageNotFoundError, OSError):   # not in the index, or AMENT_PREFIX_PATH unset
        pass
    candidates.append(Path(sys.executable).parent / name)
    for path in candidates:
        if path.is_file() and os.access(path, os.X_OK):
            return str(path)
    raise AssertionError(f'{name} not found in ' + ', '.join(map(str, candidates)) +
                         ': build with colcon and source the workspace, or pip install -e .')


def stamp(msg, t: float):
    """Set ``msg.header`` to stamp ``t`` (s) and :data:`FRAME_ID`; return ``msg``."""
    sec = int(np.floor(t))
    msg.header.stamp.sec = sec
    msg.header.stamp.nanosec = int(round((t - sec) * 1e9))
    msg.header.frame_id = FRAME_ID
    return msg


def image_msg(gray: np.ndarray, t: float, encoding: str = 'mono8') -> Image:
    """Build a ``sensor_msgs/Image`` of ``gray (H, W) uint8`` in ``encoding``, stamped ``t``."""
    msg = Image()
    for key, value in gray_to_image_fields(gray, encoding).items():
        setattr(msg, key, value)
    return stamp(msg, t)


class DdsHarness:
    """A test node (and the nodes under test) in one executor; call :meth:`start` to spin."""

    #: Default seconds :meth:`wait` and :meth:`call` give the other side.
    timeout = 10.0

    def __init__(self, name: str, *nodes, namespace: str = '') -> None:
        self.node = rclpy.create_node(name, namespace=namespace)
        self.executor = SingleThreadedExecutor()
        for n in (self.node,) + nodes:
            self.executor.add_node(n)
        self.lock = threading.Lock()
        self.inbox: Dict[str, List] = {}
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)

    def start(self) -> None:
        self.thread.start()

    def collect(self, msg_type, topic: str, qos=None) -> List:
        """Subscribe and return the (growing) list of received messages."""
        box = self.inbox.setdefault(topic, [])

        def cb(msg):
            with self.lock:
                box.append(msg)
        self.node.create_subscription(msg_type, topic, cb, qos or QoSProfile(depth=100))
        return box

    def camera_publishers(self, ns: str, timeout: float = None):
        """
        Create publishers of ``{ns}/image`` and ``{ns}/camera_info`` (sensor-data QoS).

        Returned once the node under test (``{ns}/mlofc``) subscribes to both and publishes
        ``~/segments``.
        """
        image_pub = self.node.create_publisher(Image, f'{ns}/image', qos_profile_sensor_data)
        info_pub = self.node.create_publisher(CameraInfo, f'{ns}/camera_info',
                                              qos_profile_sensor_data)
        assert self.wait(lambda: image_pub.get_subscription_count() == 1
                         and info_pub.get_subscription_count() == 1
                         and self.node.count_publishers(f'{ns}/mlofc/segments') == 1,
                         timeout), 'node did not come up'
        return image_pub, info_pub

    def wait(self, pred: Callable[[], bool], timeout: float = None) -> bool:
        end = time.monotonic() + (self.timeout if timeout is None else timeout)
        while time.monotonic() < end:
            if pred():
                return True
            time.sleep(0.01)
        return pred()

    def call(self, srv_type, name: str, request, timeout: float = None):
        timeout = self.timeout if timeout is None else timeout
        client = self.node.create_client(srv_type, name)
        assert client.wait_for_service(timeout_sec=timeout), f'no service {name}'
        future = client.call_async(request)
        assert self.wait(future.done, timeout), f'{name} did not answer'
        self.node.destroy_client(client)
        return future.result()

    def set_params(self, node_name: str, **values):
        req = SetParameters.Request()
        req.parameters = [Parameter(k, value=v).to_parameter_msg() for k, v in values.items()]
        return self.call(SetParameters, f'{node_name}/set_parameters', req).results

    def get_params(self, node_name: str, *names):
        req = GetParameters.Request()
        req.names = list(names)
        values = self.call(GetParameters, f'{node_name}/get_parameters', req).values
        return [Parameter.from_parameter_msg(ParameterMsg(name=n, value=v)).value
                for n, v in zip(names, values)]

    def close(self, *nodes) -> None:
        self.executor.shutdown()
        self.thread.join(timeout=10)
        for n in nodes:
            n.destroy_node()
        self.node.destroy_node()


def stamp_of(msg) -> float:
    """Header stamp of ``msg`` in seconds, rounded to the microsecond (for comparisons)."""
    return round(stamp_to_seconds(msg.header.stamp), 6)
