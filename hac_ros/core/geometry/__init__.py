"""The map and the floor, in SLAM units: the map index and its ray query (:mod:`reference`), the
map's shape (:mod:`map_shape`), planes (:mod:`plane`), which way is down (:mod:`down_vote`), the
floor model (:mod:`ground`), the gravity-aligned frame (:mod:`alignment`) and the values no SLAM
or HMR gives (:mod:`plausibility`). On basics and layouts.
"""
