import numpy as np

from epp_ros.core import PostureEstimator
from epp_ros.core.simulate import RangeNoise, random_posture, truck_pump
from epp_ros.health import ERROR, OK, WARN, Thresholds, assess

MODEL = truck_pump()
JOINTS = random_posture(MODEL, np.random.default_rng(0))[2]


def diagnostics_of(method, ranges):
    estimator = PostureEstimator(MODEL, method)
    estimator.update(ranges)
    return estimator.last_diagnostics


def test_good_fit_is_ok_with_the_paper_diagnostic():
    level, message, values = assess(diagnostics_of('cepp', MODEL.ranges(JOINTS)),
                                    Thresholds(), MODEL.arm_lengths)
    assert level == OK and message == 'tracking'
    assert float(values['section 1 abs error [m]']) < 1e-6
    assert values['section 1 configured [m]'] == '9.0000'


def test_chain_reports_its_predicted_uncertainty_and_nlos():
    ranges = MODEL.ranges(JOINTS)
    ranges[4, 1] += 5.0
    _, _, values = assess(diagnostics_of('chain', ranges), Thresholds(), MODEL.arm_lengths)
    assert float(values['predicted RMSE [m]']) > 0
    assert 'joint 5 predicted std [m]' in values and values['NLOS links'] == '1'


def test_levels_follow_the_thresholds():
    ranges, _ = RangeNoise(sigma=1.0).apply(MODEL.ranges(JOINTS), np.random.default_rng(1))
    diagnostics = diagnostics_of('epp1', ranges)           # lengths not held
    assert assess(diagnostics, Thresholds(), MODEL.arm_lengths)[0] == ERROR
    loose = Thresholds(arm_length_warn=100, arm_length_error=200, residual_warn=0.0,
                       residual_error=100)
    assert assess(diagnostics, loose, MODEL.arm_lengths)[0] == WARN


def test_an_unsolved_frame_is_an_error():
    level, message, _ = assess(diagnostics_of('cepp', np.full((5, 6), np.nan)), Thresholds(),
                               MODEL.arm_lengths)
    assert level == ERROR and 'insufficient_data' in message
