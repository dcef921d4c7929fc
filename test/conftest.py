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

"""Test-wide setup: every test run gets its own ROS domain and a HOME for rcl logging."""
import os
import random

import pytest

os.environ.setdefault('HOME', '/tmp')
os.environ.setdefault('MPLBACKEND', 'Agg')
for _var in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ.setdefault(_var, '1')   # as the node runs (mlofc_ros/__init__.py)
if 'ROS_DOMAIN_ID' not in os.environ:
    # 1..100 stays inside the default DDS port range; random so parallel runs do not meet
    os.environ['ROS_DOMAIN_ID'] = str(random.SystemRandom().randint(1, 100))


@pytest.fixture(scope='module')
def ros():
    """Initialise rclpy for the module's tests (real DDS in the run's own domain)."""
    import rclpy
    rclpy.init()
    yield
    rclpy.try_shutdown()
