"""The inputs and outputs in stamp order: the SLAM pose stream (:mod:`pose_stream`), time jumps
(:mod:`timeline`), poses from TF (:mod:`tf_tree`), joints and poses stamped apart
(:mod:`stamp_reach`), the maps of a stream (:mod:`map_book`), the services' requests
(:mod:`services`), and the metric stage that applies the scale and alignment to poses, joints and
the map (:mod:`metric_stage`, :mod:`pending`, :mod:`odometry`). On basics, rules, geometry and
bodies.
"""
