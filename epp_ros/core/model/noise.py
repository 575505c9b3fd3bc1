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


"""
What the estimator is told of its measurements' errors: one home, checked once.

The defaults are DW1000-class UWB links and MEMS angle sensors: a range standard deviation
of 0.1 m (plus ``eta`` per metre), a tenth of the ranges NLOS with a mean excess of 1 m,
the biases left once the configured offsets are taken off (each link's own, the part
common to all and its growth with range; ``core.model.bounds.RangeBiasPrior``), and an
outrigger set up again 0.1 m per axis from where it was surveyed (until calibrated). Every
estimator option, node parameter and method default of these names reads them here.
"""
from dataclasses import asdict, dataclass, fields
import math
import numbers

import numpy as np

__all__ = ['NoiseModel', 'DEFAULT_NOISE', 'fitted_link_bias', 'link_bias_stds']


@dataclass(frozen=True)
class NoiseModel:
    """
    The measurement errors an estimator is told, checked when made.

    Raises ValueError naming the field (as the estimator's keyword) when a value is not a
    finite number in its range.
    """

    sigma: float = 0.1                      #: m, tag-anchor range standard deviation
    eta: float = 0.0                        #: range standard deviation per metre of range
    tag_sigma: float = None                 #: m, tag-tag ranges; None: ``sigma``
    pitch_sigma: float = math.radians(0.5)  #: rad, inclinometers
    slew_sigma: float = math.radians(0.5)   #: rad, slew encoder
    nlos_fraction: float = 0.1              #: prior probability that a range is NLOS
    nlos_gamma: float = 1.0                 #: m, mean NLOS excess
    #: m, each link's own bias: one for every link, or one per link ((p, m) rows, tag-major:
    #: what a calibration leaves unknown of each, ``epp_calibrate``'s ``link_offset_std``)
    link_bias_std: float = 0.1
    common_bias_std: float = 0.25           #: m, the bias common to every link
    bias_slope_std: float = 0.01            #: m per m, its growth with range
    anchor_std: float = 0.1                 #: m per axis, where a moving anchor may stand

    def __post_init__(self):
        for field in fields(self):
            value = getattr(self, field.name)
            if value is None and field.name == 'tag_sigma':
                continue
            if field.name == 'link_bias_std' and not isinstance(value, numbers.Real):
                object.__setattr__(self, field.name, _per_link(value))
                continue
            if isinstance(value, bool) or not isinstance(value, numbers.Real) \
                    or not math.isfinite(value):
                raise ValueError(f'{field.name}: must be a finite number, got {value!r}')
            low, strict = _RANGES.get(field.name, (0.0, False))
            if value < low or strict and value == low:
                raise ValueError(f'{field.name}: must be {">" if strict else ">="} {low:g}, '
                                 f'got {value!r}')
            object.__setattr__(self, field.name, float(value))
        if self.nlos_fraction >= 1.0:
            raise ValueError(f'nlos_fraction: must be < 1, got {self.nlos_fraction!r}')

    def told(self):
        """Return the fields as a dict, ``tag_sigma`` resolved to ``sigma`` when None."""
        values = asdict(self)
        if values['tag_sigma'] is None:
            values['tag_sigma'] = values['sigma']
        return values


def _per_link(values):
    """Return per-link stds as rows of floats (a tuple of tuples); ValueError otherwise."""
    try:
        rows = () if isinstance(values, (str, bytes)) or any(
            isinstance(row, (str, bytes)) for row in values) else tuple(
            tuple(float(v) for v in row) for row in values)
    except (TypeError, ValueError):
        rows = ()
    if not rows or len({len(row) for row in rows}) != 1 or not all(
            math.isfinite(v) and v >= 0 for row in rows for v in row):
        raise ValueError(f'link_bias_std: must be a finite number >= 0 or rows of them, one '
                         f'per link, got {values!r}')
    return rows


def fitted_link_bias(link_bias_std, shape=None):
    """
    Return what a fit adds to each link's sigma for its own bias, metres.

    A fit weighs links against each other: by ``sqrt(s^2 - min(s)^2)`` of the per-link
    ``link_bias_std`` ``s``, what is unknown of each link's bias beyond the best-known
    link's. One number for every link (or the same for each) changes no weight: 0.0, and
    only the integrity checks count it.

    Parameters
    ----------
    link_bias_std : float or array_like, shape (p, m)
        As :class:`NoiseModel` holds it, metres.
    shape : tuple (p, m), optional
        The links a per-link value must cover (ValueError naming ``link_bias_std`` if not).

    Returns
    -------
    float or ndarray, shape (p, m)

    """
    stds = link_bias_stds(link_bias_std, shape)
    return 0.0 if np.ndim(stds) == 0 else np.sqrt(stds ** 2 - np.min(stds) ** 2)


def link_bias_stds(link_bias_std, shape=None):
    """
    Return ``link_bias_std`` as a float, or as an array (p, m) of ``shape``.

    Raises ValueError naming ``link_bias_std`` when a per-link value is not of ``shape``.
    """
    if np.ndim(link_bias_std) == 0:
        return float(link_bias_std)
    stds = np.asarray(link_bias_std, dtype=float)
    if shape is not None and stds.shape != tuple(shape):
        raise ValueError(f'link_bias_std: needs one number, or one per link ({shape[0]} tags x '
                         f'{shape[1]} anchors), got shape {stds.shape}')
    return stds


#: (lowest value, whether it is excluded) of the fields that must be positive; the others
#: are >= 0.
_RANGES = {'sigma': (0.0, True), 'tag_sigma': (0.0, True), 'pitch_sigma': (0.0, True),
           'slew_sigma': (0.0, True), 'nlos_gamma': (0.0, True)}

#: The defaults, for the methods' and the calibration's keyword defaults.
DEFAULT_NOISE = NoiseModel()
