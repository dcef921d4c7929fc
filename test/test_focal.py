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

"""The focal length of an uncalibrated stream: one window's evidence, the running estimate."""
import math

from mlofc_ros.pipeline import focal_covariance
from mlofc_ros.solver import segment_lines
from mlofc_ros.solver.focal import (focal_evidence, FOCAL_OBSERVABLE, FOCAL_PRIOR_LOG_SIGMA,
                                    FOCAL_WINDOW_INFORMATIVE,
                                    FocalEstimate, FocalEvidence, general_profiles)
from mlofc_ros.solver.general import fit_bodies, LineObservations
from mlofc_ros.solver.warm import result_motions
from mlofc_tools.synthetic import make_scene
import numpy as np
import pytest

F_TRUE = 550.0
SIZE = (640, 480)
CENTRE = (320.0, 240.0)


def scene(seed: int, **kwargs):
    args = {'n_frames': 10, 'noise_px': 1.0, 'image_size': SIZE, 'focal_length': F_TRUE,
            'seed': seed, 'rotation_deg': (0.3, 1.5)}
    args.update(kwargs)
    return make_scene(2, 60, **args)


def test_window_evidence_is_calibrated_on_rotating_bodies():
    """The profile's curvature gives the spread of ln f: z-scores of unit size over seeds."""
    z = []
    for seed in range(12):
        sc = scene(seed)
        ev = focal_evidence(sc.tracks, sc.labels, 2, CENTRE, 700.0, noise_var=1.0)
        assert 0.0 < ev.log_sigma < 0.05
        z.append(math.log(ev.focal / F_TRUE) / ev.log_sigma)
    rms = float(np.sqrt(np.mean(np.square(z))))
    assert 0.6 < rms < 1.6, z


def test_still_or_translating_windows_give_no_evidence():
    still = scene(1, rotation_deg=(0.0, 0.0))
    assert math.isinf(focal_evidence(still.tracks, still.labels, 2, CENTRE, 600.0).log_sigma)
    # bodies translating fast: the rotation model leaves 2x the noise the general model does
    moving = scene(2, translation_ratio=5.0)
    ev = focal_evidence(moving.tracks, moving.labels, 2, CENTRE, 600.0, noise_var=1.0)
    assert math.isinf(ev.log_sigma)
    assert math.isfinite(focal_evidence(moving.tracks, moving.labels, 2, CENTRE,
                                        600.0).log_sigma)        # its own noise: no test


def test_running_estimate_combines_windows_and_widens_when_they_disagree():
    est = FocalEstimate(800.0)
    assert est.focal == 800.0 and est.log_sigma == FOCAL_PRIOR_LOG_SIGMA
    assert not est.observable
    est.add(FocalEvidence(560.0, math.inf))                      # no evidence: no change
    assert est.focal == pytest.approx(800.0) and est.n_windows == 0
    for f in (545.0, 555.0, 550.0, 548.0):
        est.add(FocalEvidence(f, 0.02))
    assert est.focal == pytest.approx(550.0, rel=0.01)
    assert est.log_sigma == pytest.approx(0.01, rel=0.05)        # 0.02 / sqrt(4)
    assert est.observable and est.log_sigma <= FOCAL_OBSERVABLE
    # windows that disagree far beyond their own spread: the spread grows (Birge ratio)
    for f in (300.0, 900.0, 420.0):
        est.add(FocalEvidence(f, 0.02))
    assert 0.1 < est.log_sigma <= FOCAL_PRIOR_LOG_SIGMA and not est.observable
    # old windows are forgotten (memory): consistent windows bring it back
    short = FocalEstimate(800.0, memory=3)
    for f in (300.0, 900.0, 550.0, 551.0, 549.0):
        short.add(FocalEvidence(f, 0.02))
    assert short.focal == pytest.approx(550.0, rel=0.01) and short.observable
    with pytest.raises(ValueError, match='f_start'):
        FocalEstimate(math.nan)


def test_focal_covariance_is_the_first_order_change_of_the_rotation():
    """The change ``d w / d ln f = -(w_x, w_y, 0)``, checked with solves at two f."""
    sc = scene(4, rotation_deg=(2.0, 3.0), noise_px=0.0)
    eps = 0.02
    w0, w1 = (segment_lines(sc.tracks, 2, intrinsics=(f, f) + CENTRE, method='robust',
                            seed=0).angular_velocities for f in (F_TRUE, F_TRUE * math.exp(eps)))
    if np.linalg.norm(w1 - w0) > np.linalg.norm(w1[::-1] - w0):   # the bodies' order
        w1 = w1[::-1]
    changed = (w1 - w0) / eps
    expected = np.zeros_like(w0)
    expected[:, :2] = -w0[:, :2]
    assert np.allclose(changed, expected, atol=0.1 * np.abs(w0).max()), (changed, expected)
    cov = focal_covariance(w0, 0.1)
    assert np.allclose(cov, 0.01 * expected[:, :, None] * expected[:, None, :])
    assert not focal_covariance(w0, 0.0).any() and not focal_covariance(w0, math.nan).any()


def test_a_failed_refinement_is_reported_and_the_frame_kept(monkeypatch):
    """The focal evidence of a window failing (whatever the error) loses no frame."""
    import mlofc_ros.pipeline as pipeline_module

    def broken(*args, **kwargs):
        raise FloatingPointError('overflow')
    monkeypatch.setattr(pipeline_module, 'focal_evidence', broken)
    sc = make_scene(2, 60, n_frames=40, noise_px=0.5, image_size=SIZE, focal_length=F_TRUE,
                    seed=1, rotation_deg=(0.2, 0.4))
    p = pipeline_module.Pipeline(num_bodies=2, window=10, method='general')
    ids = np.arange(len(sc.tracks))
    out = [p.process_lines(ids, sc.tracks[:, k], k / 30.0, SIZE) for k in range(22)]
    failed = [r for r in out if r.problem and 'focal length not refined' in r.problem]
    assert failed and all(r.solved for r in failed)


def test_general_profile_of_a_scaled_image_is_the_profile_at_that_focal_length():
    """One batch of scaled copies gives each focal length's fit, cost scaled by s^2."""
    sc = scene(3, translation_ratio=5.0, rotation_deg=(2.0, 4.0))
    members = [np.flatnonzero(sc.labels == b) for b in range(2)]
    intrinsics = (600.0, 600.0) + CENTRE
    W = np.array([[0.01, -0.02, 0.005], [-0.02, 0.01, 0.01]])
    T = np.array([[0.3, 0.1, 1.0], [-0.5, 0.2, 1.0]])
    scales = np.array([0.8, 1.0, 1.3])
    got = general_profiles(sc.tracks, members, intrinsics, W, T, scales, iterations=4)
    for i, s in enumerate(scales):
        obs = LineObservations(sc.tracks, (600.0 * s, 600.0 * s) + CENTRE)
        want = fit_bodies(obs, members, W, T, 4)[2]
        np.testing.assert_allclose(got[i], want, rtol=1e-6)


def test_translating_bodies_give_the_general_models_evidence():
    """Bodies that translate and rotate: no rotation-model evidence, the general model's is."""
    z = []
    for seed in range(4):
        sc = scene(seed, translation_ratio=5.0, rotation_deg=(2.0, 4.0))
        res = segment_lines(sc.tracks, 2, intrinsics=(700.0, 700.0) + CENTRE, image_size=SIZE,
                            method='general', init_labels=sc.labels)
        noise = res.diagnostics.sigma_px ** 2
        assert math.isinf(focal_evidence(sc.tracks, res.labels, 2, CENTRE, 700.0,
                                         noise_var=noise).log_sigma)
        ev = focal_evidence(sc.tracks, res.labels, 2, CENTRE, 700.0, noise_var=noise,
                            motions=result_motions(res))
        assert 0.0 < ev.log_sigma < FOCAL_WINDOW_INFORMATIVE      # it counts as a window's
        z.append(math.log(ev.focal / F_TRUE) / ev.log_sigma)
        # one body alone does not count (its profile can lean far off unchecked)
        alone = np.where(res.labels == 1, -1, res.labels)
        assert math.isinf(focal_evidence(sc.tracks, alone, 2, CENTRE, 700.0, noise_var=noise,
                                         motions=result_motions(res)).log_sigma)
    assert np.all(np.abs(z) < 3.0), z


def test_a_window_solved_far_off_moves_towards_the_focal_length():
    """The general model's profile goes on past its grid's edge: f beyond the span moves f."""
    f0 = 250.0                            # the truth beyond f0 * FOCAL_EVIDENCE_SPAN
    for seed in range(4):
        sc = scene(seed, translation_ratio=5.0, rotation_deg=(2.0, 4.0))
        res = segment_lines(sc.tracks, 2, intrinsics=(f0, f0) + CENTRE, image_size=SIZE,
                            method='general', init_labels=sc.labels)
        ev = focal_evidence(sc.tracks, res.labels, 2, CENTRE, f0,
                            noise_var=res.diagnostics.sigma_px ** 2,
                            motions=result_motions(res))
        assert 1.4 * f0 < ev.focal < 1.1 * F_TRUE, (seed, ev)
        assert ev.log_sigma < FOCAL_WINDOW_INFORMATIVE, (seed, ev)


def test_the_estimate_needs_several_informative_windows():
    """One sharp window among vague ones does not make f observable (it may lean far off)."""
    est = FocalEstimate(400.0)
    for f in (420.0, 380.0, 410.0):
        est.add(FocalEvidence(f, 0.5))
    est.add(FocalEvidence(240.0, 0.01))
    assert est.n_windows == 4 and est.focal == pytest.approx(240.0, rel=0.02)
    assert est.log_sigma == pytest.approx(FOCAL_PRIOR_LOG_SIGMA) and not est.observable
    est.add(FocalEvidence(245.0, 0.01))
    est.add(FocalEvidence(238.0, 0.01))
    assert est.observable
