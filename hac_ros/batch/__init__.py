"""``hac batch``: many recordings calibrated in parallel, on a process pool or as Ray tasks.

:func:`~hac_ros.batch.runner.batch` replays each input recording
(:func:`hac_ros.replay.replayer.replay`, the same parameters and mode for all) into
``DIR/<name>``, where ``<name>`` is the input's file or directory name without a
``.mcap``/``.db3``/``.bag`` suffix (:func:`~hac_ros.batch.jobs.recording_name`), and writes
``DIR/summary.csv`` and ``DIR/summary.md`` (docs/batch.md).

One recording is one call of :func:`~hac_ros.batch.jobs.run_job`, in a worker of a process pool
(``spawn``: the caller may have imported rclpy, whose threads a fork would copy half-way) or as a
Ray task (``ray``); both call the same function with the same arguments, so their outputs are
identical. Per recording:

- the output appears atomically (the replay stages it), then a completion marker
  ``DIR/<name>.done.json`` is written: the input's fingerprint (path, and each file's size and
  modification time), the parameters and the mode, and the summary row. ``resume`` skips an
  input whose marker matches and whose output exists, and redoes any other (its output and marker
  removed first). A Ray task that is retried after its worker died finds the same state;
- what hac_ros logs meanwhile (the replay's notices, its summary, the evaluation) goes to
  ``DIR/logs/<name>.log``, through a logging handler (:func:`~hac_ros.batch.jobs.job_log`; the
  worker's stdout and stderr are left alone);
- any error is that row's one-line reason (status ``failed``), and leaves no output behind.

Usage errors (:class:`~hac_ros.core.basics.errors.HacError`, raised before any recording is started;
:class:`~hac_ros.core.basics.errors.ArgumentError` where an argument is to blame): no or missing
inputs, two inputs with the same name, an existing output without ``resume``, ``ray`` without Ray or
with an address where no Ray cluster answers.
"""
