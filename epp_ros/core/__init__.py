"""Plain numerical library of epp_ros: geometry, estimators, simulation. No ROS imports."""
from .estimators import METHODS, RANGE_METHODS, PostureEstimator
from .model import BoomModel
from .nedm import nearest_edm

__all__ = ['BoomModel', 'PostureEstimator', 'METHODS', 'RANGE_METHODS', 'nearest_edm']
