"""hac_ros: metric scale for monocular SLAM from the people in view.

Importing this package imports nothing from ROS; the node lives in :mod:`hac_ros.ros.node`.
"""
__version__ = '0.1.0'
