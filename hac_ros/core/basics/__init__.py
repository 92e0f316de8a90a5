"""The core's vocabulary, below every other room: errors, the numeric helpers (int-ns stamps,
the median), rigid transforms and similarities, the records the calibrator hands back
(:mod:`outputs`), the machinery of a parameter set (:mod:`param_fields`) and printable names.
Imports nothing else of the core.
"""
