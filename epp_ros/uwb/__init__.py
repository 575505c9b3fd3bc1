"""Device I/O for DWM1000 UWB modules, without ROS."""
