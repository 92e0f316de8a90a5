"""People from pixels (docs/people.md): a camera's images to each person's metric landmarks,
``hac_people_node`` and ``hac people``.

:mod:`~hac_ros.people.lifting` (the 6-DoF fit, pure numpy) needs nothing else; the model, the
images, the node and the offline command need the ``[people]`` extra (MediaPipe, OpenCV), which
:mod:`~hac_ros.people.extra` imports with a message naming the install command. Importing this
package imports neither.
"""
