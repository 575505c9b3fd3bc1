"""epp_ros: live boom posture of a concrete pump from UWB ranges."""
