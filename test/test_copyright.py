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

"""ament_copyright, as `colcon test` runs it; a header check with the same rule without ROS."""
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]


@pytest.mark.copyright
@pytest.mark.linter
def test_copyright():
    try:
        from ament_copyright.main import main
    except ImportError:
        header = (ROOT / '.ci' / 'license_header.txt').read_text()
        files = [*ROOT.glob('mlofc_ros/**/*.py'), *ROOT.glob('test/**/*.py'), ROOT / 'setup.py']
        missing = [str(f.relative_to(ROOT)) for f in files
                   if f.stat().st_size and not f.read_text().startswith(header)]
        assert not missing, 'files without the Apache-2.0 header: %s' % missing
        return
    rc = main(argv=['.', 'test'])
    assert rc == 0, 'Found errors'
