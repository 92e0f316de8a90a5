import sys; sys.path.insert(0, '/work/static/bench'); sys.path.insert(0, '/work/static')
import numpy as np
from _people_scenes import video_frames
from hac_ros.people.frontend import PeopleFromImages
from hac_ros.people.lifting import Camera
from hac_ros.people.model import PoseModel
people = PeopleFromImages(PoseModel())
out = {}
for index, rgb in video_frames(int(sys.argv[1])):
    h, w = rgb.shape[:2]
    K = np.array([[700.0, 0, w / 2], [0, 700.0, h / 2], [0, 0, 1.0]])
    out[index] = people.process(rgb, Camera(K=K, width=w, height=h)).joints_cam
np.save('/tmp/st/vtest_joints.npy', np.array([out], dtype=object), allow_pickle=True)
print(len(out))
