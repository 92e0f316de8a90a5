"""From samples to a scale: the rolling estimator (:mod:`estimator`), its sorted window and
streaming median (:mod:`sorted_window`), each sample's weight in stamp time
(:mod:`stamp_weights`), the log-scale filter (:mod:`scale_filter`), a segment's offline scale
(:mod:`segment`) and the authors' literal method (:mod:`literal`). On basics and rules.
"""
