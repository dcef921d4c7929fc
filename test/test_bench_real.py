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
"""``python -m mlofc_tools.bench real``: the motion proxy on hand-made frames, a quick run."""
import math
import pathlib
import re
from types import SimpleNamespace

from mlofc_tools.bench import __main__ as dispatcher
from mlofc_tools.bench import real
import numpy as np
import pytest

SEQUENCE_DIR = pathlib.Path(real.REAL_DIR) / real.SEQUENCE


def _result(ids, segments, labels=None):
    ids = np.asarray(ids)
    return SimpleNamespace(track_ids=ids, segments=np.asarray(segments, float),
                           labels=np.full(len(ids), -1) if labels is None else np.asarray(labels))


def test_motion_proxies_split_sliding_from_moving() -> None:
    earlier = real.track_table(_result([7, 3], [[0, 0, 10, 0], [0, 5, 0, 15]]))
    assert list(earlier[0]) == [3, 7]
    # track 3 slides 4 px along itself, track 7 moves 3 px across itself, track 9 is new
    later = _result([9, 3, 7], [[5, 5, 6, 6], [0, 9, 0, 19], [0, 3, 10, 3]])
    normal = real.track_motion(earlier, later, 'normal')
    midpoint = real.track_motion(earlier, later, 'midpoint')
    assert math.isnan(normal[0]) and math.isnan(midpoint[0])
    np.testing.assert_allclose(normal[1:], [0.0, 3.0], atol=1e-12)
    np.testing.assert_allclose(midpoint[1:], [4.0, 3.0], atol=1e-12)
    with pytest.raises(ValueError):
        real.track_motion(earlier, later, 'speed')


def test_score_frame_finds_the_moving_body() -> None:
    labels = np.array([1, 1, 1, 0, -1, 0, 0, 1, 1])
    motion = np.array([5.0, 3, 9, 4, 6, 0.1, 0.2, 0.3, 1.0])    # last: neither
    s = real.score_frame(labels, motion, 2.0)
    assert (s['moving'], s['still'], s['body']) == (5, 3, 1)
    assert s['on_body'] == 0.6 and s['unlabelled'] == 0.2
    assert abs(s['still_other'] - 2 / 3) < 1e-12
    s = real.score_frame(np.array([-1, -1]), np.array([3.0, np.nan]), 2.0)
    assert (s['moving'], s['body'], s['on_body']) == (1, -1, 0.0)
    assert math.isnan(s['still_other'])


def test_the_hand_region_is_left_out_of_the_second_score() -> None:
    # frame 5 against frame 0: track 1 (midpoint u 5, v 5: in the hand's region) and track 2
    # (u 405) both move 3 px across themselves; left out, track 1 is neither moving nor still
    first = _result([1, 2], [[0, 5, 10, 5], [400, 5, 410, 5]])
    moved = _result([1, 2], [[0, 8, 10, 8], [400, 8, 410, 8]], labels=[0, 1])
    results = {0: first, real.LAG: moved}
    every = real.score_run(results, 2.0)
    handless = real.score_run(results, 2.0, leave_out=real.HAND_REGION)
    assert [s['frame'] for s in every] == [real.LAG] and every[0]['moving'] == 2
    assert handless[0]['moving'] == 1 and handless[0]['on_body'] == 1.0


def test_summary_reads_the_goal_on_the_moving_phase() -> None:
    # frame 40 is before the moving phase; frame 48 has every segment on the moving body
    shares = ((40, 0.2, 1.0), (48, 1.0, 0.0), (49, 0.95, 1.0), (50, 0.5, 1.0))
    scores = [{'frame': f, 'moving': 10, 'still': 4, 'body': 1, 'on_body': x,
               'unlabelled': 0.0, 'still_other': y} for f, x, y in shares]
    row = real.summary_row('robust', scores, 48, np.array([2.0, 4.0]), np.array([10.0]))
    named = dict(zip(real.SUMMARY_HEADERS, row))
    assert named['goal'] == 'NOT met' and abs(named['frames right both ways %'] - 100 / 3) < 1e-9
    assert row[1] == '3 / 3' and abs(row[3] - 245 / 3) < 1e-9 and abs(row[5] - 200 / 3) < 1e-9
    assert row[-1] == 0.3
    assert 'real' in dispatcher.BENCHMARKS


@pytest.mark.skipif(not (SEQUENCE_DIR / 'frames').is_dir(),
                    reason=f'real sequence not found in {SEQUENCE_DIR}')
def test_real_quick_writes_report_and_picture(tmp_path: pathlib.Path) -> None:
    assert real.main(['--quick', '--out', str(tmp_path)]) == 0
    text = (tmp_path / 'README.md').read_text()
    assert 'python -m mlofc_tools.bench real --quick' in text
    lines = text.splitlines()
    for headers in (real.SUMMARY_HEADERS, real.FRAME_HEADERS):
        assert '| ' + ' | '.join(headers) + ' |' in lines
    summary = [ln for ln in lines if ln.startswith('| robust | ')]
    # the summary of each proxy and without the hand, and the per-frame rows 48, 53, 58 of
    # frames 30-60
    assert len(summary) == 3 and '## The same runs without the hand' in lines
    rows = [ln.split('|')[1].strip() for ln in lines if re.match(r'\| \d+ \| robust \|', ln)]
    assert rows == ['48', '53', '58']
    png = tmp_path / 'visp_cube.png'
    assert png.is_file() and png.stat().st_size > 10000
