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
import importlib.util
import os
from pathlib import Path
import random

import pytest

os.environ.setdefault('HOME', '/tmp')
os.environ.setdefault('MPLBACKEND', 'Agg')
for _var in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ.setdefault(_var, '1')   # as the node runs (mlofc_ros/__init__.py)
if 'ROS_DOMAIN_ID' not in os.environ:
    # 1..100 stays inside the default DDS port range; random so parallel runs do not meet
    os.environ['ROS_DOMAIN_ID'] = str(random.SystemRandom().randint(1, 100))

#: Modules whose every test is marked ``ros`` and which import ROS (rclpy, message packages,
#: rosbags) at the top: a run that deselects ``ros`` where ROS is not installed (``make
#: test-noble``) leaves them out instead of failing to import them.
ROS_ONLY_MODULES = ('test_bag.py', 'test_node.py', 'test_node_robustness.py')


def pytest_ignore_collect(collection_path: Path, config: pytest.Config):
    """Leave out :data:`ROS_ONLY_MODULES` in a ``-m 'not ros'`` run without rclpy."""
    if (collection_path.name in ROS_ONLY_MODULES
            and 'not ros' in (config.getoption('markexpr') or '')
            and importlib.util.find_spec('rclpy') is None):
        return True
    return None


@pytest.fixture(scope='module')
def ros():
    """Initialise rclpy for the module's tests (real DDS in the run's own domain)."""
    import rclpy
    rclpy.init()
    yield
    rclpy.try_shutdown()
