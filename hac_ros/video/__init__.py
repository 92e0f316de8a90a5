"""``hac video``: a metric camera trajectory, a metric map and the people in the world from a
video alone, on a CPU (docs/video.md). Needs the ``[video]`` extra (pycolmap) and ``[people]``."""
