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
"""Dispatch ``python -m mlofc_tools.bench NAME [options]`` to ``mlofc_tools.bench.NAME.main``."""
import importlib
import sys
from typing import List, Optional

BENCHMARKS = {
    'paper': 'the paper experiments (Fig. 2-5): misclassification and motion error vs noise',
    'frontend': 'line detection and tracking on rendered and real sequences',
    'hopkins': 'real line tracks built from Hopkins155 point tracks',
    'hopkins_stream': "Hopkins155 line tracks streamed through general's warm path (the node's)",
    'accuracy': 'robust solver vs floor, outliers, multi-frame, model selection, solver speed',
    'covariance': 'NEES of the published angular-velocity covariance on rendered scenes',
    'pipeline': 'per-stage timings of the whole per-frame pipeline vs LSD alone',
    'ros': 'highest image rate the running node keeps up with, and its latency',
    'live': 'spinning boxes published to the running node in real time (method general)',
    'lane': "the node's solver lane replayed offline with fixed delays (method general)",
    'step': 'one warm solver update of general against LSD alone, by number of lines',
    'soak': 'resident memory over a long run of the pipeline (10,000 frames)',
    'spinning': 'boxes spinning about their own centres through the pipeline: robust vs general',
    'degraded': 'the default pipeline on blurred, noisy and compressed frames of spinning boxes',
    'real': 'visp_cube (real, no ground truth) scored by a motion proxy: robust vs general',
    'focal': 'the focal length estimated online without calibration: general vs robust',
    'count': 'the number of bodies found online: a line stream that changes, real video',
    'tradeoff': 'speed vs tracking quality over detector_scale, detect_every, bridge_crossings',
}


def run_all() -> int:
    """
    Run every benchmark with its defaults, in turn; returns the worst exit code.

    One failing benchmark does not stop the others (each writes its own report).
    """
    worst = 0
    for name in BENCHMARKS:
        print(f'=== python -m mlofc_tools.bench {name}', file=sys.stderr, flush=True)
        try:
            code = int(importlib.import_module(f'mlofc_tools.bench.{name}').main([]) or 0)
        except Exception as exc:  # noqa: B902 (report it and go on with the next one)
            print(f'=== {name} failed: {type(exc).__name__}: {exc}', file=sys.stderr)
            code = 1
        worst = max(worst, code)
    return worst


def main(argv: Optional[List[str]] = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ('-h', '--help'):
        print('usage: python -m mlofc_tools.bench NAME [options]\n')
        for name, text in BENCHMARKS.items():
            print(f'  {name:10s} {text}')
        print(f'  {"all":10s} every benchmark above with its defaults (make bench)')
        return 0
    name = argv.pop(0)
    if name == 'all':
        if argv:
            print('bench all takes no options (each benchmark runs with its defaults)',
                  file=sys.stderr)
            return 2
        return run_all()
    if name not in BENCHMARKS:
        print(f'unknown benchmark {name!r}; choose from {sorted(BENCHMARKS)}', file=sys.stderr)
        return 2
    module = importlib.import_module(f'mlofc_tools.bench.{name}')
    return int(module.main(argv) or 0)


if __name__ == '__main__':
    sys.exit(main())
