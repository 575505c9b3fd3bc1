"""Thin rclpy nodes: parameters, topics and timing around the plain modules."""
