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
"""Smoke runs of ``python -m mlofc_tools.bench pipeline|ros|live|soak --quick``: reports."""
import os
import pathlib
import tempfile

from mlofc_tools.bench import pipeline, soak
import numpy as np
import pytest


def test_pipeline_quick_writes_report(tmp_path: pathlib.Path) -> None:
    assert pipeline.main(['--quick', '--out', str(tmp_path)]) == 0
    text = (tmp_path / 'README.md').read_text()
    assert 'python -m mlofc_tools.bench pipeline --quick' in text
    assert '## Stages (median / p95 ms per frame)' in text
    assert '## Where the mean goes: frames with and without detection' in text
    assert '## Calls per frame (machine-independent)' in text
    assert 'rendered 320x240' in text and 'process / LSD' in text
    png = tmp_path / 'pipeline.png'
    assert png.is_file() and png.stat().st_size > 1000


def test_split_row_counts_both_kinds_of_frame() -> None:
    # two detection frames of 20 ms and three others of 4 ms, LSD 10 ms: the detection frames
    # are 2x LSD and 40 / 52 of the time
    r = {'detected': np.array([1.0, 0, 0, 1, 0]), 'total': np.array([20.0, 4, 4, 20, 4]),
         'lsd': np.full(5, 10.0)}
    det_n, det_ms, det_x, det_share, n, ms, x, share = pipeline._split_row(r)
    assert (det_n, n) == (2, 3) and (det_ms, ms) == (20.0, 4.0) and (det_x, x) == (2.0, 0.4)
    assert abs(det_share - 40 / 52) < 1e-12 and abs(share - 12 / 52) < 1e-12


def test_calls_per_frame_are_counted_the_same_on_every_run() -> None:
    # the count does not depend on the machine's speed or load: after the first run (lazy
    # imports, caches) every run of the same frames counts the same calls
    seq = pipeline.rendered_sequences([(320, 240)], 6, 1, 0)[0]
    pipeline.count_calls(seq)
    a, b = pipeline.count_calls(seq), pipeline.count_calls(seq)
    np.testing.assert_array_equal(a['calls'], b['calls'])
    assert a['detected'][0] == 1.0 and np.all(a['calls'] > 100)


def test_pipeline_takes_node_parameters(tmp_path: pathlib.Path) -> None:
    argv = ['--quick', '-p', 'detect_every:=4', '-p', 'detector_scale:=0.5', '--out',
            str(tmp_path)]
    assert pipeline.main(argv) == 0
    assert '`detect_every:=4`, `detector_scale:=0.5`' in (tmp_path / 'README.md').read_text()
    with pytest.raises(SystemExit):
        pipeline.main(['--quick', '-p', 'detector_scale:=2.0', '--out', str(tmp_path)])


def test_read_visp_camera(tmp_path: pathlib.Path) -> None:
    xml = tmp_path / 'cube.xml'
    xml.write_text('<conf><camera>\n<u0>338.5</u0> <v0>234.5</v0>\n<px>547.7</px>'
                   '<py>542.0</py></camera></conf>')
    assert pipeline.read_visp_camera(str(xml)) == (547.7, 542.0, 338.5, 234.5)
    xml.write_text('<conf><camera><u0>1</u0></camera></conf>')
    assert pipeline.read_visp_camera(str(xml)) is None
    assert pipeline.read_visp_camera(str(tmp_path / 'missing.xml')) is None


def test_soak_quick_writes_report(tmp_path: pathlib.Path) -> None:
    assert soak.main(['--quick', '--out', str(tmp_path)]) == 0
    text = (tmp_path / 'README.md').read_text()
    assert 'Status: complete. 20 frames' in text
    assert 'Growth end - start' in text
    assert soak.rss_mb() > 1.0


@pytest.mark.ros
def test_ros_quick_writes_report(tmp_path: pathlib.Path) -> None:
    pytest.importorskip('rclpy')
    from mlofc_tools.bench import ros
    os.environ.setdefault('HOME', tempfile.gettempdir())
    assert ros.main(['--quick', '--out', str(tmp_path)]) == 0
    text = (tmp_path / 'README.md').read_text()
    assert '## Per rate' in text and 'kept up' in text
    # both rates ran, and at 5 Hz the node answered at least one 320x240 frame
    rows = [ln for ln in text.splitlines() if ln.startswith('| 5 |') or ln.startswith('| 10 |')]
    assert len(rows) == 2
    assert int(rows[0].split('|')[5]) >= 1
    assert (tmp_path / 'ros.png').is_file()


def test_ros_process_times_are_read_back_by_frame_range(tmp_path: pathlib.Path) -> None:
    from mlofc_tools.bench import ros
    stats = tmp_path / 'node_stats.json'
    wall, cpu = ros.read_proc_times(stats, 0, 5)          # nothing written yet
    assert wall.shape == cpu.shape == (0,)
    pathlib.Path(ros.proc_times_path(stats)).write_text('1.5 1.25\n2.0 nan\n3.0 2.5\n')
    wall, cpu = ros.read_proc_times(stats, 1, 3)
    np.testing.assert_array_equal(wall, [2.0, 3.0])
    assert np.isnan(cpu[0]) and cpu[1] == 2.5


@pytest.mark.ros
def test_live_quick_writes_report(tmp_path: pathlib.Path) -> None:
    pytest.importorskip('rclpy')
    from mlofc_tools.bench import live
    os.environ.setdefault('HOME', tempfile.gettempdir())
    assert live.main(['--quick', '--out', str(tmp_path)]) == 0
    text = (tmp_path / 'README.md').read_text()
    assert '## Over the seeds' in text and '## Every run' in text
    row = [ln for ln in text.splitlines() if ln.startswith('| own2 | general | 0 | 10 |')]
    assert len(row) == 1
    published, answered, unsolved, carried, dropped = (int(x)
                                                       for x in row[0].split('|')[5:10])
    # every frame that reached the node was tracked; the solver answered some of them, the
    # running fit some of the others
    assert published == 15 and answered >= 1 and dropped == 0
    # (carried: also frames answered while being solved, whose own cloud came late)
    assert carried <= answered <= published


def test_ros_headline_names_the_limit_or_says_it_is_above() -> None:
    from mlofc_tools.bench import ros

    def row(rate: float, dropped: int) -> dict:
        return {'rate': rate, 'dropped': dropped, 'published': 100,
                'answered': 100 - dropped, 'lat_median': 10.0, 'lat_p99': 30.0}
    assert ros.rate_headline([]) == '- No rate was run.'
    assert 'none of the rates' in ros.rate_headline([row(5, 3), row(10, 0)])
    text = ros.rate_headline([row(5, 0), row(10, 0), row(20, 4), row(30, 0)])
    assert '**10 Hz**' in text and 'At 20 Hz it no longer does' in text
    text = ros.rate_headline([row(5, 0), row(10, 0)])
    assert '**10 Hz**' in text and 'the limit lies above it' in text


def test_covariance_quick_writes_report(tmp_path: pathlib.Path) -> None:
    from mlofc_tools.bench import covariance
    assert covariance.main(['--quick', '--out', str(tmp_path)]) == 0
    text = (tmp_path / 'README.md').read_text()
    rows = {ln.split('|')[1].strip(): ln.split('|') for ln in text.splitlines()
            if ln.startswith('| own2 general') or ln.startswith('| cam2+bg robust')}
    assert set(rows) == {'own2 general', 'cam2+bg robust'}
    # the rotation-only model on its own scene: every box scored, NEES a plain number
    robust = rows['cam2+bg robust']
    assert int(robust[9]) == 2 and float(robust[10]) > 0
