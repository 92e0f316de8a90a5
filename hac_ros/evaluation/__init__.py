"""Metrics against ground truth (``hac eval``) and figures (``hac plot``)."""
