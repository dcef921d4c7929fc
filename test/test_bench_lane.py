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
"""``python -m mlofc_tools.bench lane``: the lane's delays by job, the tables, a short run."""
from mlofc_ros.frame import Observation
from mlofc_ros.lane import SolveJob
from mlofc_tools.bench import __main__ as dispatcher
from mlofc_tools.bench import lane
import numpy as np


def test_each_job_answers_after_its_kinds_delay():
    obs = Observation.skip(0.0, None, 'a test', 6)
    jobs = {'search': SolveJob(obs, {'n_bodies': -1}, 0),
            'full': SolveJob(obs, {'n_bodies': -1, 'init_motions': None}, 0),
            'rescan': SolveJob(obs, {'n_bodies': -1, 'init_motions': None}, 0, rescan=True)}
    for kind, job in jobs.items():
        assert lane.job_kind(job) == kind
        for scale in (1.0, 0.5, 0.01):
            fixed = lane.FixedDelayLane(scale)
            fixed.submit(job)                      # a failing job: its exception is the answer
            polls = [fixed.poll() for _ in range(lane.DELAYS[kind] + 2)]
            waited = next(i for i, p in enumerate(polls) if p is not None)
            assert waited == max(1, round(lane.DELAYS[kind] * scale))
            assert isinstance(polls[waited][1], Exception)


def _record(scene, seed, scale, wrong, errs, running_fit, method='general'):
    score = {'wrong': wrong, 'unassigned': 0.1, 'omega_err': np.array(errs)}
    return {'scene': scene, 'method': method, 'seed': seed, 'scale': scale, 'score': score,
            'late_wrong': wrong, 'running_fit': running_fit}


def test_the_tables_over_seeds_and_per_run():
    records = [_record('own2+bg', 0, 1.0, 0.10, [np.nan, 0.01, 0.5], 40),
               _record('own2+bg', 1, 1.0, 0.30, [np.nan, 0.02, 0.07], 60),
               _record('own2+bg', 0, 0.0, 0.01, [np.nan, 0.01, 0.02], 0),
               _record('own2+bg', 0, 1.0, 0.05, [np.nan, 0.01, 0.02], 20, 'auto')]
    summary = lane.summary_rows(records)
    assert [row[:4] for row in summary] == [['own2+bg', 'auto', 'x1', 1],
                                            ['own2+bg', 'general', 'every frame in turn', 1],
                                            ['own2+bg', 'general', 'x1', 2]]
    assert np.allclose(summary[2][4:6], [20.0, 30.0])
    assert summary[2][8:10] == ['2 of 4', '3 of 4'] and summary[2][10] == 50.0
    rows = lane.build_rows(records)
    assert rows[0][1] == 'auto' and rows[1][3] == 'every frame in turn'
    assert rows[2][7] == '1 / 50' and rows[2][8] == '1 of 2'


def test_a_short_replay_writes_its_report(tmp_path):
    assert 'lane' in dispatcher.BENCHMARKS
    assert lane.main(['--scenes', 'own2+bg', '--seeds', '0', '--delays', '0,1', '--frames',
                      '12', '--jobs', '1', '--out', str(tmp_path)]) == 0
    text = (tmp_path / 'README.md').read_text()
    assert 'every frame in turn' in text and '| own2+bg | general | x1 | 1 |' in text
    assert '| own2+bg | auto | x1 | 1 |' in text
    assert (tmp_path / 'lane.png').stat().st_size > 0


def test_an_unknown_scene_is_refused_with_the_known_ones():
    import pytest
    with pytest.raises(SystemExit):
        lane.parse_args(['--scenes', 'own2+bg,nowhere'])
    assert lane.parse_args(['--scenes', 'own3']).scenes == ['own3']
