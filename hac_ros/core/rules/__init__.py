"""What the calibrator is told and what it tells: the parameters (:mod:`params`, every name,
default and range), the one table of reasons for not being OK (:mod:`reasons`), the status they
make (:mod:`health`) and what a run's statuses said (:mod:`status_shares`). On basics and layouts.
"""
