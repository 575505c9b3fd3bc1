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
    diagnostics = dict(diagnostics_of('epp2', MODEL.ranges(JOINTS)))
    thresholds = Thresholds()
    for error, level in ((0.01, OK), (0.1, WARN), (1.0, ERROR)):
        diagnostics['section_lengths'] = MODEL.arm_lengths + [0, 0, error, 0, 0]
        assert assess(diagnostics, thresholds, MODEL.arm_lengths)[0] == level
    diagnostics['section_lengths'] = MODEL.arm_lengths
    diagnostics['range_residual_rms'] = 1.0
    assert assess(diagnostics, thresholds, MODEL.arm_lengths)[0] == WARN
    diagnostics['range_residual_rms'] = 3.0
    assert assess(diagnostics, thresholds, MODEL.arm_lengths)[0] == ERROR
    diagnostics.update(range_residual_rms=0.0, converged=False)
    assert assess(diagnostics, thresholds, MODEL.arm_lengths)[:2] == (
        WARN, 'solver stopped before converging')


def test_epp1_is_not_judged_on_lengths_it_does_not_model():
    ranges, _ = RangeNoise(sigma=0.1).apply(MODEL.ranges(JOINTS), np.random.default_rng(1))
    diagnostics = diagnostics_of('epp1', ranges)
    assert np.max(diagnostics['arm_length_error']) > Thresholds().arm_length_warn
    assert assess(diagnostics, Thresholds(), MODEL.arm_lengths)[0] == OK


def test_an_unsolved_frame_is_an_error():
    level, message, _ = assess(diagnostics_of('cepp', np.full((5, 6), np.nan)), Thresholds(),
                               MODEL.arm_lengths)
    assert level == ERROR and 'insufficient_data' in message
