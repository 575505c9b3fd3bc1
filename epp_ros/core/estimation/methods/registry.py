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
The posture methods by name, and how one is built from the estimator's options.

``PostureEstimator(model, method, **options)`` hands each method the options its
constructor (or a base's, or a delegate's) takes: one table of names, one factory.
"""
import inspect

from epp_ros.core.estimation.methods.baselines import SDPMethod, SRLSMethod, TPSMMethod
from epp_ros.core.estimation.methods.chain import ChainMethod
from epp_ros.core.estimation.methods.epp import CEPP, EPP1, EPP2
from epp_ros.core.estimation.methods.field_cepp import FieldCEPP
from epp_ros.core.estimation.methods.track import TrackMethod

__all__ = ['METHODS', 'RANGE_METHODS', 'method_options', 'make_method']

#: Every method by the name the estimator, the node and the tools know it by.
METHODS = {'epp1': EPP1, 'epp2': EPP2, 'cepp_paper': CEPP, 'cepp': FieldCEPP,
           'chain': ChainMethod, 'track': TrackMethod, 'srls': SRLSMethod, 'sdp': SDPMethod,
           'tpsm': TPSMMethod}

#: Methods that work from UWB ranges alone (what the estimator node receives).
RANGE_METHODS = [name for name, cls in METHODS.items() if 'ranges' in cls.inputs]


def method_options(method):
    """Return the names of the options ``method``'s constructor (and its bases') take."""
    names = set()
    cls = METHODS[method]
    for cls in cls.__mro__ + getattr(cls, 'delegates', ()):
        if '__init__' in vars(cls):
            names |= {name for name, parameter in
                      inspect.signature(cls.__init__).parameters.items()
                      if parameter.kind in (parameter.KEYWORD_ONLY,
                                            parameter.POSITIONAL_OR_KEYWORD)
                      and name not in ('self', 'model')}
    return names


def make_method(model, method, options):
    """Return ``method`` for ``model``, given those of ``options`` (a dict) it takes."""
    own = method_options(method)
    return METHODS[method](model, **{name: value for name, value in options.items()
                                     if name in own})
