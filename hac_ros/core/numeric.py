"""Constants shared across the core: the robust-statistics factors the estimator, the odometry
covariance and the offline schedule use, and the nanoseconds in a second (stamps are integer
nanoseconds everywhere)."""
# normal samples: sigma per unit of median absolute deviation, and the standard error of a median
# of n samples, MEDIAN_STD_ERROR * sigma / sqrt(n)
MAD_TO_SIGMA = 1.4826
MEDIAN_STD_ERROR = 1.2533
NS = 1_000_000_000  # nanoseconds per second
