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
"""``python -m mlofc_tools.bench focal``: the summaries and the report on hand-made runs."""
import argparse
import math

from mlofc_tools.bench import __main__ as dispatcher
from mlofc_tools.bench import focal
import numpy as np


def _run(method: str, sequence: str, start: int, focal_px, spread, truth=None) -> dict:
    n = len(focal_px)
    return {'method': method, 'sequence': sequence, 'label': f'from frame {start}',
            'start': start, 'n': 2, 'truth': truth, 'focal': list(focal_px),
            'log_sigma': list(spread), 'ms': [2.0] * n, 'given_ms': [1.0] * n}


def test_a_run_is_summarized_from_its_last_frame_and_its_first_observable_one(tmp_path):
    nan = math.nan
    r = _run('general', 'visp_cube', 20, [nan, 500.0, 520.0, 540.0, 560.0],
             [nan, 0.69, 0.2, 0.05, 0.04], truth=548.0)
    s = focal.summarize_run(r, window=1)
    assert s['first_observable'] == 23                   # frame 3 of a run started at 20
    assert s['observable_share'] == 0.5                  # 2 of the 4 solved frames
    assert s['state'] == 'observable' and s['last_f'] == 560.0
    assert s['error'] == 560.0 / 548.0 - 1.0
    assert s['z'] == math.log(560.0 / 548.0) / 0.04
    assert s['cpu_ratio_mean'] == 2.0 and s['cpu_ratio_max'] == 2.0
    r['summary'] = s
    other = _run('general', 'visp_cube', 40, [nan, 300.0], [nan, 0.69], truth=548.0)
    other['summary'] = focal.summarize_run(other, window=1)
    assert other['summary']['state'] == 'not observable'
    assert other['summary']['first_observable'] is None
    args = argparse.Namespace(window=10)
    text = focal.build_report(args, [], [r, other], 1.0, 'abc1234')
    assert '| general | visp_cube | from frame 20 |' in text
    assert '560 +-4%, 300 +-69%' in text and '| 87 |' in text     # 560 / 300 - 1
    focal.plot([r, other], tmp_path / 'focal.png')
    assert (tmp_path / 'focal.png').stat().st_size > 1000
    assert 'focal' in dispatcher.BENCHMARKS


def test_the_runs_cover_every_method_sequence_and_start_frame():
    args = focal.parse_args(['--quick', '--methods', 'robust'])
    assert args.seed_list == [0] and args.method_list == ['robust']
    assert focal.parse_args([]).method_list == ['general', 'robust']
    out = focal.run_frames([np.zeros((60, 80), np.uint8)] * 3, 2, 10, 'robust')
    assert len(out['focal']) == 3 and all(math.isnan(f) for f in out['focal'])
