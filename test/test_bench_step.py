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
"""``python -m mlofc_tools.bench step``: the table, the goal's line, a short run."""
from mlofc_tools.bench import __main__ as dispatcher
from mlofc_tools.bench import step


def _result(step_ms, lsd_ms, held=4, calls=6000.0, wrong=0.02):
    ms = {'LSD': [lsd_ms] * 4, 'step': [step_ms] * 4, 'step with a rescan': [5 * step_ms] * 4,
          'robust warm': [1.0] * 4}
    return {'ms': ms, 'held': held, 'tried': 4, 'calls': calls, 'wrong': wrong}


def test_the_table_and_the_goal_line():
    results = {200: _result(20.0, 10.0), 50: _result(2.0, 10.0, held=3)}
    rows = step.build_rows(results)
    assert [row[:3] for row in rows] == [[50, '3 of 4', 2.0], [200, '4 of 4', 2.0]]
    assert rows[1][4] == 2.0 and rows[1][6] == 10.0 and rows[1][-1] == 6000
    assert '**2.00x** LSD alone' in step.headline(results) and 'NOT met' in step.headline(results)
    assert 'met' in step.headline({200: _result(2.0, 10.0)})
    assert 'not read' in step.headline({50: _result(2.0, 10.0)})


def test_a_short_run_writes_its_report(tmp_path):
    assert 'step' in dispatcher.BENCHMARKS
    assert step.main(['--lines', '30', '--scenes', '1', '--reps', '1',
                      '--out', str(tmp_path)]) == 0
    text = (tmp_path / 'README.md').read_text()
    assert '| 30 | ' in text and (tmp_path / 'step.png').is_file()
