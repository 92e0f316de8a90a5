"""Every reason ``hac_people_node`` gives for an image it did not turn into people, or a person
it dropped: its one table (the core's is :mod:`hac_ros.core.rules.reasons`, hac_node's). Keys appear
in its ``/diagnostics`` as ``rejected.<key>``; the people the lifting left out as
``people_dropped.<key>`` (:data:`PEOPLE_DROPPED`); images skipped on purpose as
``dropped.rate_cap``, ``dropped.overload`` and ``dropped.lost``; images processed with a warning
under the key of :data:`WARNINGS` (docs/people.md, "What the node does with each image").
"""
from __future__ import annotations

from hac_ros.people.lifting import MIN_LANDMARKS

# reason -> what it means (the first line logged of each)
REJECTIONS = {
    'wrong_encoding': 'an image of an encoding the node does not read (Image: rgb8, bgr8, mono8, '
                      'rgba8, bgra8; CompressedImage: JPEG or PNG)',
    'empty_image': 'an image of no pixels',
    'corrupt_image': 'an image whose bytes do not match its size, or do not decode',
    'no_camera_info': 'an image before any CameraInfo',
    'camera_info_size_mismatch': 'an image whose size is not the CameraInfo\'s',
    'camera_info_invalid': 'a CameraInfo with an invalid K, size, ROI or distortion, or a '
                           'principal point outside the image',
    'processing_error': 'an error inside the model or the lifting (logged with its traceback)',
}

# key -> what it means: images processed all the same, counted under the key itself in
# /diagnostics, the status WARN for the period, the first logged
WARNINGS = {
    'image_too_small': 'an image in which no person of person_min_height_px fits the person '
                       'detector\'s 64 x 128 px window, even scaled as it searches: only the '
                       'landmarker looked at it',
    'stamp_zero': 'an image stamped 0 (a driver without a clock): the rate cap counts arrival '
                  'time instead, and the joints keep the stamp (hac_node refuses it)',
    'stamp_backwards': 'an image stamped before the one before it: the rate cap counts arrival '
                       'time instead',
}

# Why a person was not lifted (hac_ros.people.lifting.lift_person; counted by the node and
# `hac people`)
PEOPLE_DROPPED = {
    'too_few_landmarks': f'fewer than {MIN_LANDMARKS} landmarks in the image',
    'no_hips_shoulders': 'no hip or no shoulder in the image',
    'fit_failed': 'the 6-DoF fit did not converge, or put the person behind the camera or far '
                  'from their landmarks',
}


def markdown_table() -> str:
    """docs/people.md's table of every key (held to this by ``make docs`` and its test)."""
    rows = ['| key in /diagnostics | the image or person | meaning |', '|---|---|---|']
    rows += [f'| `rejected.{key}` | not published | {text} |' for key, text in REJECTIONS.items()]
    rows += [f'| `{key}` | published, status WARN | {text} |' for key, text in WARNINGS.items()]
    rows += [f'| `people_dropped.{key}` | the person left out | {text} |'
             for key, text in PEOPLE_DROPPED.items()]
    return '\n'.join(rows) + '\n'
