"""Recordings through the core: the feeder (inputs in the node's order) and the replay."""
