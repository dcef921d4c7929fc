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
General rigid motion from lines over three or more frames: ``method='general'``.

Each body moves by a rotation AND a translation per frame (the paper's model is rotation
only). The package's modules, in the order they build on each other:

- :mod:`.eigen`: closed-form smallest eigenpair of batches of 3x3 matrices;
- :mod:`.model`: the line model, each line's unknowns projected out or marginalised;
- :mod:`.fit`: Levenberg-Marquardt fit of a body's motion, several runs (and bodies) in
  lockstep;
- :mod:`.starts`: a body's starting motions (scans, pivot starts, Necker reversal);
- :mod:`.search`: the segmentation, cold (:func:`general_search`) or warm
  (:func:`general_warm`);
- :mod:`.covariance`: the published rotation's covariance.
"""
from .covariance import basin_spread, body_covariance, body_covariances
from .fit import (fit_bodies, fit_body, rescale_translation, rescale_translations, RESCALES,
                  ROBUST_SCALE, robust_scale)
from .model import (general_costs, Intrinsics, line_residuals, LineObservations,
                    marginal_costs, marginal_residuals)
# the oracles of bench hopkins run the search's own steps
from .search import _best_costs, _fit_each_body, _robust_sigma2  # noqa: F401
from .search import (assign_bodies, assign_fitted, background_labels, fitted_start,
                     general_search, general_warm, marginal_segmentation, measured_noise,
                     NOISE_FACTOR, position_costs, POSITION_PRIOR, POSITION_WEIGHT,
                     SIGMA_FLOOR_PX, spatial_labels, WARM_INLIERS)
from .starts import (fit_bodies_multistart, fit_body_multistart, necker_mirror, PIVOT_KEEP,
                     pivot_picks, PIVOT_RATES, pivot_starts, PIVOT_W, polish_bodies,
                     polish_body, T_SCALES, T_STARTS)

__all__ = ['assign_bodies', 'assign_fitted', 'background_labels', 'basin_spread',
           'body_covariance', 'body_covariances', 'fit_bodies', 'fit_bodies_multistart',
           'fit_body', 'fit_body_multistart', 'fitted_start', 'general_costs', 'general_search',
           'general_warm', 'Intrinsics', 'line_residuals', 'LineObservations', 'marginal_costs',
           'marginal_residuals', 'marginal_segmentation', 'measured_noise', 'necker_mirror',
           'NOISE_FACTOR', 'PIVOT_KEEP', 'pivot_picks', 'PIVOT_RATES', 'pivot_starts', 'PIVOT_W',
           'polish_bodies', 'polish_body', 'position_costs', 'POSITION_PRIOR', 'POSITION_WEIGHT',
           'RESCALES', 'rescale_translation', 'rescale_translations', 'ROBUST_SCALE',
           'robust_scale', 'SIGMA_FLOOR_PX', 'spatial_labels', 'T_SCALES', 'T_STARTS',
           'WARM_INLIERS']
