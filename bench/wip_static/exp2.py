import sys; sys.path.insert(0, '/work/static')
import numpy as np
from collections import defaultdict
from hac_ros.core.calibrator import Calibrator
from hac_ros.core.params import HacParams
from hac_ros.core.outputs import DiagnosticsOut, SampleOut
from hac_ros.core.numeric import NS
from hac_ros.core.human_filter import PersonTracker
from hac_ros.core.layouts.blazepose33 import LAYOUT
data = np.load('/tmp/st/vtest_joints.npy', allow_pickle=True)[0]
K = np.array([[700.0, 0, 384], [0, 700.0, 288], [0, 0, 1.0]])
cal = Calibrator(HacParams(joint_layout='blazepose33', static_camera=True))
cal.add_camera_info(K, 768, 576)
outs = []; tr = PersonTracker(); heights = defaultdict(list)
for index, joints in sorted(data.items()):
    stamp = int(index / 10 * NS)
    out = cal.add_joints(stamp, joints, 'camera'); outs += out
    ids = tr.follow(stamp, LAYOUT.root_of(joints)) if len(joints) else []
    for o in out:
        if isinstance(o, SampleOut) and o.accepted and o.person < len(ids) and ids[o.person] >= 0:
            heights[ids[o.person]].append(o.scale)
outs += cal.flush()
s = [o for o in outs if isinstance(o, DiagnosticsOut)][-1].status
pp = [np.median(h) for h in heights.values() if len(h) >= 5]
print(f'h {s.camera_height_m:.3f} +- {s.spread:.3f} pitch {s.camera_pitch_deg:.1f} roll {s.camera_roll_deg:.1f} samples {s.samples}; {len(pp)} people spread {np.std(pp)/np.median(pp):.3f}')
from hac_ros.core.outputs import NoticeOut
for o in outs:
    if isinstance(o, NoticeOut) and o.cause == 'floor_refined': print(o.stamp_ns / NS, o.text[:60])
print('converged', s.converged, 'publishing', s.publishing, s.scale)
