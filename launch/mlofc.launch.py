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
"""
Launch mlofc_node with its camera topics remapped and a parameter file.

Arguments (``ros2 launch mlofc_ros mlofc.launch.py --show-args``):

- ``image``: the camera's image topic (sensor_msgs/Image), default ``/camera/image_raw``
- ``camera_info``: its CameraInfo topic, default ``/camera/camera_info``
- ``params_file``: parameter file, default the installed ``config/mlofc.yaml`` (all defaults)
- ``namespace``: the node's namespace, default none
- ``node_name``: the node's name, default ``mlofc``

Example::

    ros2 launch mlofc_ros mlofc.launch.py image:=/cam/image_raw camera_info:=/cam/camera_info \
        params_file:=$HOME/mlofc.yaml
"""
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare

#: (name, default, description) of every launch argument.
ARGUMENTS = (
    ('image', '/camera/image_raw', 'image topic (sensor_msgs/Image) to segment'),
    ('camera_info', '/camera/camera_info', 'CameraInfo topic of the image'),
    ('params_file', PathJoinSubstitution([FindPackageShare('mlofc_ros'), 'config',
                                          'mlofc.yaml']),
     'parameter file (/**: ros__parameters: form)'),
    ('namespace', '', 'namespace of the node'),
    ('node_name', 'mlofc', 'name of the node'),
)


def generate_launch_description() -> LaunchDescription:
    """Return the launch description: the arguments and the node."""
    node = Node(
        package='mlofc_ros',
        executable='mlofc_node',
        name=LaunchConfiguration('node_name'),
        namespace=LaunchConfiguration('namespace'),
        parameters=[LaunchConfiguration('params_file')],
        remappings=[('image', LaunchConfiguration('image')),
                    ('camera_info', LaunchConfiguration('camera_info'))],
        output='screen',
        emulate_tty=True,
    )
    return LaunchDescription(
        [DeclareLaunchArgument(name, default_value=default, description=description)
         for name, default, description in ARGUMENTS] + [node])
