"""Every reason ``hac_people_node`` gives for an image it did not turn into people, or a person
it dropped: its one table (the core's is :mod:`hac_ros.core.reasons`, hac_node's). Keys appear in
its ``/diagnostics`` as ``rejected.<key>``; the lifting's as ``people_dropped.<key>``
(:data:`hac_ros.people.lifting.REASONS`); images skipped on purpose as ``dropped.rate_cap``,
``dropped.overload`` and ``dropped.lost`` (docs/people.md, "What the node does with each image").
"""
from __future__ import annotations

# reason -> what it means (the first line logged of each)
REJECTIONS = {
    'wrong_encoding': 'an image of an encoding the node does not read (Image: rgb8, bgr8, mono8, '
                      'rgba8, bgra8; CompressedImage: JPEG or PNG)',
    'empty_image': 'an image of no pixels',
    'corrupt_image': 'an image whose bytes do not match its size, or do not decode',
    'no_camera_info': 'an image before any CameraInfo',
    'camera_info_size_mismatch': 'an image whose size is not the CameraInfo\'s',
    'camera_info_invalid': 'a CameraInfo with an invalid K, size or distortion',
    'processing_error': 'an error inside the model or the lifting (logged with its traceback)',
}
