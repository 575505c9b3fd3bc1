# Copyright 2026 epp_ros developers
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


"""The noise model every estimator is told: one home for its defaults and its rules."""
import math

from epp_ros.core import PostureEstimator
from epp_ros.core.estimation import ESTIMATOR_OPTIONS
from epp_ros.core.estimation.methods import CEPP, EPP1
from epp_ros.core.model import (DEFAULT_NOISE, fitted_link_bias, link_bias_stds, NoiseModel,
                                SensorNoise)
from epp_ros.core.simulation import truck_pump
import numpy as np
import pytest

MODEL = truck_pump()


def test_the_defaults_live_in_the_noise_model_and_everything_reads_them():
    assert DEFAULT_NOISE == NoiseModel() and DEFAULT_NOISE.sigma == 0.1
    assert {name: ESTIMATOR_OPTIONS[name] for name in DEFAULT_NOISE.told()} == {
        **DEFAULT_NOISE.told(), 'tag_sigma': None}
    cepp = CEPP(MODEL)
    assert cepp.sigma == DEFAULT_NOISE.sigma and cepp.eta == DEFAULT_NOISE.eta
    assert SensorNoise().range_sigma == DEFAULT_NOISE.sigma
    assert SensorNoise().pitch_sigma == DEFAULT_NOISE.pitch_sigma == math.radians(0.5)


@pytest.mark.parametrize('field, value, message', [
    ('sigma', 0.0, 'sigma: must be > 0'),
    ('sigma', -0.1, 'sigma: must be > 0'),
    ('sigma', float('nan'), 'sigma: must be a finite number'),
    ('sigma', True, 'sigma: must be a finite number'),
    ('sigma', '0.1', 'sigma: must be a finite number'),
    ('eta', -1e-3, 'eta: must be >= 0'),
    ('tag_sigma', 0.0, 'tag_sigma: must be > 0'),
    ('pitch_sigma', float('inf'), 'pitch_sigma: must be a finite number'),
    ('nlos_fraction', 1.0, 'nlos_fraction: must be < 1'),
    ('nlos_fraction', -0.1, 'nlos_fraction: must be >= 0'),
    ('nlos_gamma', 0.0, 'nlos_gamma: must be > 0'),
    ('link_bias_std', -0.1, 'link_bias_std: must be >= 0'),
    ('anchor_std', np.nan, 'anchor_std: must be a finite number'),
])
def test_one_rule_per_field_named_as_the_caller_named_it(field, value, message):
    with pytest.raises(ValueError, match=message):
        NoiseModel(**{field: value})
    # The estimator, and a method built alone, refuse it with the same words.
    with pytest.raises(ValueError, match=message):
        PostureEstimator(MODEL, 'cepp', **{field: value})
    if field in ('sigma', 'eta', 'nlos_fraction', 'nlos_gamma'):
        with pytest.raises(ValueError, match=message):
            EPP1(MODEL, **{field: value})


def test_values_are_kept_as_floats_and_tag_sigma_follows_sigma():
    noise = NoiseModel(sigma=np.float32(0.2), eta=np.int64(0))
    assert type(noise.sigma) is float and noise.sigma == pytest.approx(0.2)
    assert noise.told()['tag_sigma'] == noise.sigma
    assert NoiseModel(tag_sigma=0.3).told()['tag_sigma'] == 0.3
    with pytest.raises(Exception):
        noise.sigma = 1.0                  # frozen: checked once, never changed


def test_each_links_own_bias_may_be_told_one_per_link():
    per_link = np.full((MODEL.n_sections, MODEL.n_anchors), 0.02)
    per_link[-1] = 0.3                                  # the tip's links barely known
    noise = NoiseModel(link_bias_std=per_link)
    # Kept as rows of floats: the model stays frozen, hashable and comparable.
    assert noise.link_bias_std == tuple(tuple(row) for row in per_link.tolist())
    assert noise == NoiseModel(link_bias_std=per_link.tolist()) and hash(noise)
    np.testing.assert_array_equal(link_bias_stds(noise.link_bias_std, per_link.shape),
                                  per_link)
    # The fit weighs links by what is unknown beyond the best-known link's.
    np.testing.assert_allclose(fitted_link_bias(per_link), np.sqrt(per_link ** 2 - 0.02 ** 2))
    assert fitted_link_bias(0.1) == 0.0 == fitted_link_bias(np.full((2, 3), 0.1)).max()
    with pytest.raises(ValueError, match=r'link_bias_std: needs one number, or one per link '
                                         r'\(5 tags x 6 anchors\), got shape \(6, 5\)'):
        PostureEstimator(MODEL, 'chain', link_bias_std=per_link.T)
    with pytest.raises(ValueError, match='link_bias_std: needs one number'):
        fitted_link_bias(per_link[:-1], per_link.shape)


@pytest.mark.parametrize('value', [[[0.1, -0.1]], [[0.1, np.nan]], [[0.1], [0.1, 0.2]], [],
                                   [0.1, 0.2], '0.1', ['0.1']])
def test_a_per_link_bias_that_is_not_rows_of_stds_is_refused(value):
    with pytest.raises(ValueError, match='link_bias_std: must be a finite number >= 0 or rows'):
        NoiseModel(link_bias_std=value)
