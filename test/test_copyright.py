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
ament_copyright, or where it is not installed the same rules.

ament_copyright is not on PyPI; without it :mod:`copyright_rules` applies its rules (the
files it visits, the first comment block, the notice pattern, the Apache-2.0 header in order,
and LICENSE and CONTRIBUTING.md at the repository root).
"""
import os
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]


@pytest.mark.copyright
@pytest.mark.linter
def test_copyright():
    try:
        from ament_copyright.main import main
    except ImportError:
        from copyright_rules import main
    cwd = os.getcwd()
    os.chdir(ROOT)   # colcon runs the tests from the package folder; so does this
    try:
        rc = main(argv=['.', 'test'])
    finally:
        os.chdir(cwd)
    assert rc == 0, 'Found errors'


def test_the_rules_flag_a_missing_notice_and_a_foreign_license(tmp_path):
    from copyright_rules import main
    hdr = (ROOT / '.ci' / 'license_header.txt').read_text()
    (tmp_path / 'good.py').write_text(hdr + 'x = 1\n')
    assert main([str(tmp_path)]) == 0
    (tmp_path / 'mit.py').write_text('# Copyright 2026 Someone\n# MIT License\nx = 1\n')
    (tmp_path / 'bare.py').write_text('x = 1\n')
    (tmp_path / '.git').mkdir()          # a repository root needs LICENSE and CONTRIBUTING.md
    assert main([str(tmp_path)]) == 1
