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
"""``python -m mlofc_tools.bench degraded``: the degradations, the table, a report."""
from mlofc_tools.bench import __main__ as dispatcher
from mlofc_tools.bench import degraded
import numpy as np
import pytest


def _frames():
    img = np.zeros((40, 60), np.uint8)
    img[:, 30:] = 200                                         # one vertical step edge
    return [img, img.copy()]


def test_each_degradation_does_what_it_says():
    frames = _frames()
    clean = degraded.degrade(frames, degraded.CONDITIONS['clean'], 0)
    assert all(np.array_equal(a, b) for a, b in zip(clean, frames))
    blur = degraded.degrade(frames, [('blur', 1.5)], 0)[0]
    assert 0 < blur[20, 29] < 200 and blur.dtype == np.uint8       # the step is smoothed
    motion = degraded.degrade(frames, [('motion', 9)], 0)[0]
    assert np.count_nonzero((motion[20] > 0) & (motion[20] < 200)) == 8   # a 9 px ramp
    assert np.array_equal(motion[:, 0], frames[0][:, 0])             # vertical: unchanged
    noisy = degraded.degrade(frames, [('noise', 10.0)], 3)
    again = degraded.degrade(frames, [('noise', 10.0)], 3)
    assert all(np.array_equal(a, b) for a, b in zip(noisy, again))  # the seed's draws
    assert not np.array_equal(noisy[0], noisy[1])                   # each frame its own
    assert 5.0 < np.std(noisy[0][:, :20].astype(float)) < 15.0
    jpeg = degraded.degrade(frames, [('jpeg', 30)], 0)[0]
    assert jpeg.shape == frames[0].shape and not np.array_equal(jpeg, frames[0])
    with pytest.raises(ValueError, match='unknown degradation'):
        degraded.degrade(frames, [('fog', 1.0)], 0)


def _record(scene, condition, seed, wrong, omega_err):
    score = {'wrong': wrong, 'unassigned': 0.1, 'omega_err': np.array(omega_err),
             'tracked_5': 0.9, 'id_switch_pct': 1.0, 'precision': 0.95, 'segments': 100.0}
    return {'scene': scene, 'condition': condition, 'seed': seed, 'score': score}


def test_the_summary_reads_over_the_seeds_in_the_conditions_order():
    records = [_record('own2+bg', 'JPEG q30', 0, 0.04, [np.nan, 0.02, 0.5]),
               _record('own2+bg', 'JPEG q30', 1, 0.08, [np.nan, 0.05, 0.01]),
               _record('own2+bg', 'clean', 0, 0.01, [np.nan, 0.01, 0.02])]
    rows = degraded.summary_rows(records)
    assert [row[1] for row in rows] == ['clean', 'JPEG q30']
    jpeg = rows[1]
    assert jpeg[2] == 2 and jpeg[3] == pytest.approx(6.0) and jpeg[4] == pytest.approx(8.0)
    assert jpeg[6] == '3 of 4' and jpeg[7] == '50'


def test_a_report_from_given_runs(tmp_path):
    assert 'degraded' in dispatcher.BENCHMARKS

    def runner(item):
        scene, condition, seed, _ = item
        return _record(scene, condition, seed, 0.02, [np.nan, 0.03])

    assert degraded.main(['--scenes', 'own2+bg', '--conditions', 'clean,noise 5', '--seeds',
                          '0,1', '--jobs', '1', '--out', str(tmp_path)], runner=runner) == 0
    text = (tmp_path / 'README.md').read_text()
    assert '| own2+bg | noise 5 | 2 | 2 |' in text and (tmp_path / 'degraded.png').is_file()
    with pytest.raises(SystemExit):
        degraded.parse_args(['--conditions', 'fog'])
    with pytest.raises(SystemExit):
        degraded.parse_args(['--seeds', ','])


def test_one_run_through_the_pipeline():
    rec = degraded.run_one(('own2+bg', 'JPEG q75', 0, 12))
    s = rec['score']
    assert rec['condition'] == 'JPEG q75' and s['matched'] > 0
    assert 0.0 <= s['wrong'] <= 1.0 and 0.0 < s['precision'] <= 1.0 and s['segments'] > 10
