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
"""``python -m mlofc_tools.bench tradeoff`` (grid, front, a small run) and ``bench all``."""
import pathlib

from mlofc_ros import params
from mlofc_ros.pipeline import make_tracker
from mlofc_tools.bench import tradeoff
from mlofc_tools.bench.__main__ import BENCHMARKS


def test_make_tracker_follows_the_node_parameters() -> None:
    p = dict(params.defaults(), detect_every=5, detector_scale=0.5, bridge_crossings=False,
             min_segment_length=30.0)
    tracker = make_tracker(p)
    assert tracker.detect_every == 5 and tracker.min_length == 30.0
    assert tracker.detect_every_max == 12                       # on demand by default
    assert tracker.detector.scale == 0.5 and tracker.detector.bridge is False
    assert tracker.detector.min_length == 30.0 and tracker.detector.backend == 'lsd_resize'


def test_settings_are_every_combination() -> None:
    args = tradeoff.parse_args(['--scales', '1.0,0.5', '--every', '3', '--bridge', 'on,off',
                                '--max', 'fixed'])
    assert tradeoff.settings(args) == [(1.0, 3, True, 0), (1.0, 3, False, 0),
                                       (0.5, 3, True, 0), (0.5, 3, False, 0)]
    assert tradeoff.params_of((0.5, 3, False, 0)) == {
        'detector_scale': 0.5, 'detect_every': 3, 'bridge_crossings': False,
        'detect_every_max': 3}
    # on demand: a maximum not above detect_every is the fixed rate, listed once
    args = tradeoff.parse_args(['--scales', '0.8', '--every', '3,12', '--bridge', 'on'])
    assert tradeoff.settings(args) == [(0.8, 3, True, 0), (0.8, 3, True, 12),
                                       (0.8, 12, True, 0)]
    assert tradeoff.setting_text((0.8, 3, True, 12)) == (
        'detector_scale:=0.8 detect_every:=3 bridge_crossings:=true detect_every_max:=12')


def test_front_keeps_settings_nothing_beats_on_both() -> None:
    records = [{'mean_ratio': r, 'tracked_5': t}
               for r, t in ((0.5, 0.80), (0.6, 0.90), (0.7, 0.85), (0.9, 0.95), (1.0, 0.95))]
    assert tradeoff.pareto(records) == [True, True, False, True, True]


def test_small_run_writes_report(tmp_path: pathlib.Path) -> None:
    assert 'tradeoff' in BENCHMARKS
    argv = ['--scales', '0.5', '--every', '3,6', '--bridge', 'off', '--max', 'fixed',
            '--frames', '6',
            '--seeds', '0', '--timing-frames', '8', '--out', str(tmp_path)]
    assert tradeoff.main(argv) == 0
    text = (tmp_path / 'README.md').read_text()
    assert 'python -m mlofc_tools.bench tradeoff --scales 0.5' in text
    rows = [line for line in text.splitlines() if line.startswith('| 0.5 |')]
    assert len(rows) == 2 and {row.split('|')[2].strip() for row in rows} == {'3', '6'}
    assert '2 / 2' in text or '1 / 2' in text or '0 / 2' in text
    png = tmp_path / 'tradeoff.png'
    assert png.is_file() and png.stat().st_size > 1000


def test_bench_all_runs_every_benchmark_and_reports_the_worst(monkeypatch) -> None:
    import importlib
    import types

    from mlofc_tools.bench import __main__ as bench_main
    ran = []

    def fake_import(name: str) -> types.SimpleNamespace:
        short = name.rsplit('.', 1)[1]

        def main(argv):
            ran.append((short, list(argv)))
            if short == 'paper':
                raise RuntimeError('boom')
            return 0
        return types.SimpleNamespace(main=main)
    monkeypatch.setattr(importlib, 'import_module', fake_import)
    assert bench_main.main(['all']) == 1          # paper failed, the others still ran
    assert ran == [(name, []) for name in BENCHMARKS]
    assert bench_main.main(['all', '--quick']) == 2 and len(ran) == len(BENCHMARKS)


def test_pooled_score_weights_sequences_and_goal_per_sequence() -> None:
    from mlofc_tools.bench import frontend
    scores = [{'tracked_5': 1.0, 'windows': 30, 'id_switch_pct': 0.5, 'transitions': 100},
              {'tracked_5': 0.5, 'windows': 10, 'id_switch_pct': float('nan'),
               'transitions': 0}]
    assert frontend.pooled_score(scores, 'tracked_5', 'windows') == 0.875
    assert frontend.pooled_score(scores, 'id_switch_pct', 'transitions') == 0.5
    assert frontend.meets_goal(scores[0]) and not frontend.meets_goal(scores[1])
    assert not frontend.meets_goal({'tracked_5': 0.95, 'id_switch_pct': 1.0})
