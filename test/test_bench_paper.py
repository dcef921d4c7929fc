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

"""Smoke test of ``python -m mlofc_tools.bench paper --quick`` and the report helpers."""
import pytest

from mlofc_tools.bench import common


def test_markdown_table():
    table = common.markdown_table(['a', 'b'], [['x', 1.23456], ['y', float('nan')]])
    assert '| x | 1.23 |' in table and '| y | — |' in table


def test_paper_bench_quick(tmp_path):
    try:
        from mlofc_ros.solver import METHODS, segment_lines  # noqa: F401
    except ImportError as exc:
        pytest.skip(f'solver not importable yet: {exc}')
    from mlofc_tools.bench import paper
    rc = paper.main(['--quick', '--trials', '1', '--jobs', '1', '--out', str(tmp_path)])
    assert rc == 0
    text = (tmp_path / 'paper.md').read_text()
    assert 'floor (unweighted)' in text and 'Fig. 5' in text
    for fig in ('fig2', 'fig3', 'fig4', 'fig5'):
        assert (tmp_path / f'paper_{fig}.png').stat().st_size > 1000
