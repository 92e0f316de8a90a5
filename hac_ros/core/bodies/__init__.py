"""The people, in metres, camera frame: which joint touches the floor (:mod:`contact`), who
stands (:mod:`posture`), the checks a person passes (:mod:`person_checks`), one person's scale
sample (:mod:`sample`), the joints' conventions and their check (:mod:`conventions`,
:mod:`convention_check`) and the world joints' filter (:mod:`human_filter`). On basics, rules,
layouts and geometry.
"""
