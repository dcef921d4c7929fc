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
"""Where the project's shared data lives (benchmarks and tests only; the node needs none)."""
import os
import pathlib

#: The checkout's root (the folder holding ``package.xml``).
REPO_ROOT = pathlib.Path(__file__).resolve().parents[2]


def shared_data_dir() -> pathlib.Path:
    """``$MLOFC_SHARED_DATA``, else ``shared/data`` beside the checkout (as CI lays it out)."""
    env = os.environ.get('MLOFC_SHARED_DATA')
    if env:
        return pathlib.Path(env)
    for candidate in (REPO_ROOT.parent / 'shared' / 'data', pathlib.Path('/work/shared/data')):
        if candidate.is_dir():
            return candidate
    return REPO_ROOT.parent / 'shared' / 'data'
