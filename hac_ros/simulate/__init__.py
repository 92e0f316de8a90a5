"""Scenario simulator: recordings with ground truth that look like what a robot sees.

``make_scenario`` builds the arrays (no I/O), ``write_recording`` writes them as a rosbag2
recording with the input and ground-truth topics (docs/interface.md), ``feed_scenario`` feeds them
to a Calibrator.
"""
from hac_ros.simulate.feed import feed_scenario, scenario_events
from hac_ros.simulate.scenarios import SCENARIOS, Scenario, make_scenario
from hac_ros.simulate.writer import write_recording

__all__ = ['SCENARIOS', 'Scenario', 'feed_scenario', 'make_scenario', 'scenario_events',
           'write_recording']
