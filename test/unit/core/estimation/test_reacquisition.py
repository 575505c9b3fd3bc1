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

"""The re-acquisition policy: when a frame is solved afresh, when the warm start goes."""
from epp_ros.core.estimation.reacquisition import Reacquisition
import numpy as np


def test_rejected_frames_are_searched_first_often_then_every_tenth():
    """Across the drop of the warm start too: garbage costs a search per ten frames."""
    policy = Reacquisition(reset_after_failures=10)
    searched, dropped = [], []
    for failure in range(1, 41):
        if policy.due_for_search():
            searched.append(failure)
        if policy.failed('inconsistent'):
            dropped.append(failure)
    assert searched == [1, 2, 4, 8, 10, 16, 20, 30, 32, 40]
    assert dropped == [10]


def test_the_warm_start_goes_after_so_many_failures_and_not_for_an_undetermined_fit():
    policy = Reacquisition(reset_after_failures=3)
    assert [policy.failed('inconsistent') for _ in range(5)] == [False, False, True,
                                                                 False, False]
    assert not any(policy.failed(status) for status in ['ambiguous', 'unobservable'] * 5)
    policy.failed('implausible')
    policy.succeeded()
    assert policy.failures == 0 and not policy.failed('implausible')
    policy.failed('inconsistent')
    policy.reset_after_failures = 1                 # lowered past the count: dropped once
    assert [policy.failed('inconsistent') for _ in range(3)] == [True, False, False]


def test_a_fit_calling_half_a_tags_links_blocked_is_doubted_once_a_period():
    ranges = np.ones((2, 4))
    ranges[1, 3] = np.nan                           # tag 2 has three links
    blocked = np.zeros((2, 4), bool)
    blocked[1, :2] = True                           # two of its three: suspicious
    policy = Reacquisition()
    assert policy.suspicious(blocked, ranges, stamp=10.0)
    policy.searched(10.0, ambiguous=False)
    assert not policy.suspicious(blocked, ranges, stamp=10.5)      # within the period
    assert policy.suspicious(blocked, ranges, stamp=11.0)
    one = np.zeros((2, 4), bool)
    one[0, 0] = True                                # one link of four: not
    assert not policy.suspicious(one, ranges, stamp=20.0)


def test_an_ambiguous_search_keeps_every_frame_in_doubt_until_one_is_not():
    policy = Reacquisition()
    clear = np.zeros((1, 4), bool)
    policy.searched(0.0, ambiguous=True)
    assert policy.suspicious(clear, np.ones((1, 4)), stamp=0.1)
    policy.searched(0.1)                            # a failed search: the doubt stands
    assert policy.in_doubt
    policy.searched(0.2, ambiguous=False)
    assert not policy.suspicious(clear, np.ones((1, 4)), stamp=0.3)
