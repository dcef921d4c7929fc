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
The raw line detectors: OpenCV's LSD, FLD and EDLines, on the image resized or not.

A backend is a callable ``gray (H, W) uint8 -> (M, 4) segments px`` (or None when it finds
nothing) in the pixels of the input image (pixel centres at integer coordinates).
"""
from typing import Callable, Optional, Union

import cv2
from mlofc_ros.segments.common import has_ximgproc
import numpy as np

#: Backends understood by :func:`make_backend` (``fld``/``edlines`` need opencv-contrib).
BACKENDS = ('lsd', 'lsd_resize', 'fld', 'edlines')

RawDetector = Callable[[np.ndarray], Optional[np.ndarray]]
Backend = Union[str, RawDetector]


def check_backend(backend: Backend) -> None:
    """Raise ``ValueError`` unless ``backend`` is a callable or one of :data:`BACKENDS`."""
    if not callable(backend) and backend not in BACKENDS:
        raise ValueError(f'unknown backend {backend!r}; expected one of {BACKENDS} '
                         'or a callable')


def make_backend(backend: Backend, scale: float, min_length: float,
                 lsd_bins: int) -> RawDetector:
    """
    Return the raw detector ``backend`` running at ``scale`` (a callable is returned as is).

    ``'lsd'`` sub-samples with LSD's own Gaussian scale, the others run on the image resized
    by ``scale`` (area average); ``min_length`` (px of the input image) sets the shortest
    line of FLD and EDLines, ``lsd_bins`` the gradient-norm bins of LSD (OpenCV's ``n_bins``).
    """
    check_backend(backend)
    if callable(backend):
        return backend
    # OpenCV's defaults after refine and scale: sigma_scale, quant, ang_th, log_eps,
    # density_th; then n_bins, the number of gradient-norm bins LSD sorts pixels into
    lsd_args = (0.6, 2.0, 22.5, 0.0, 0.7, lsd_bins)
    if backend == 'lsd':
        return _lsd_scaled(scale, lsd_args)
    if backend in ('fld', 'edlines') and not has_ximgproc():
        raise ValueError(f'backend {backend!r} needs opencv-contrib (cv2.ximgproc)')
    shortest = max(int(min_length * scale * 0.5), 5)
    if backend == 'lsd_resize':
        det = cv2.createLineSegmentDetector(cv2.LSD_REFINE_STD, 1.0, *lsd_args)
        run: RawDetector = (lambda g: det.detect(g)[0])
    elif backend == 'fld':
        run = cv2.ximgproc.createFastLineDetector(shortest).detect
    else:
        run = _edlines(shortest)
    return run if scale == 1.0 else _resized(run, scale)


def _lsd_scaled(scale: float, lsd_args: tuple) -> RawDetector:
    """Return LSD with its own Gaussian sub-sampling at ``scale``."""
    lsd = cv2.createLineSegmentDetector(cv2.LSD_REFINE_STD, scale, *lsd_args)
    # OpenCV's LSD reports scaled coordinates shifted by -(1/scale - 1)/2 px (measured on
    # ideal step edges: -0.125 px at 0.8, -0.5 px at 0.5); put them on pixel centres
    shift = np.float32(0.5 * (1.0 / scale - 1.0))

    def run_lsd(g: np.ndarray) -> Optional[np.ndarray]:
        out = lsd.detect(g)[0]
        return None if out is None else out.reshape(-1, 4) + shift
    return run_lsd


def _edlines(shortest: int) -> RawDetector:
    """Return EdgeDrawing's line detector (lines of at least ``shortest`` px)."""
    ed = cv2.ximgproc.createEdgeDrawing()
    p = cv2.ximgproc.EdgeDrawing.Params()
    p.MinLineLength = shortest
    ed.setParams(p)

    def run(g: np.ndarray) -> Optional[np.ndarray]:
        ed.detectEdges(g)
        return ed.detectLines()
    return run


def _resized(run: RawDetector, f: float) -> RawDetector:
    """Return ``run`` on the image resized by ``f`` (area average), in full-size pixels."""
    def scaled(g: np.ndarray) -> Optional[np.ndarray]:
        small = cv2.resize(g, None, fx=f, fy=f, interpolation=cv2.INTER_AREA)
        out = run(small)
        if out is None or len(out) == 0:
            return out
        # pixel centres: u_full = (u_small + 0.5) / f - 0.5
        return (np.asarray(out, dtype=np.float32).reshape(-1, 4) + 0.5) / f - 0.5
    return scaled
