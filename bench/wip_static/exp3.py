import sys; sys.path.insert(0, '/work/static')
import numpy as np
from collections import defaultdict
from hac_ros.core.human_filter import PersonTracker
from hac_ros.core.layouts.blazepose33 import LAYOUT, HEELS, FOOT_INDICES, ANKLES
from hac_ros.core.numeric import NS
data = np.load('/tmp/st/vtest_joints.npy', allow_pickle=True)[0]
tr = PersonTracker(); feet = defaultdict(list); ups = []
for index, joints in sorted(data.items()):
    stamp = int(index / 10 * NS)
    if not len(joints): continue
    ids = tr.follow(stamp, LAYOUT.root_of(joints))
    for p, j in enumerate(joints):
        up = LAYOUT.up_axis(j)
        if np.isfinite(up).all(): ups.append(up / np.linalg.norm(up))
        c = j[list(HEELS + FOOT_INDICES)]
        if ids[p] >= 0 and np.isfinite(c).all():
            feet[ids[p]].append(c)
body = -np.linalg.eigh(np.array(ups).T @ np.array(ups))[1][:, -1]
if body @ np.mean(ups, 0) > 0: body = -body
def heights(n):
    hs = []
    for k, f in feet.items():
        if len(f) < 5: continue
        lows = [max(float(n @ x) for x in fr) for fr in f]  # lowest contact along down
        hs.append(np.median(lows))
    hs = np.array(hs); return np.median(hs), np.std(hs) / np.median(hs), len(hs)
allfeet = np.concatenate([np.concatenate(f) for f in feet.values()])
# pooled LSQ of lowest contacts
lows = np.array([max(fr, key=lambda x: x @ body) for f in feet.values() for fr in f])
c = lows - lows.mean(0); pooled = np.linalg.eigh(c.T @ c)[1][:, 0]; pooled *= np.sign(pooled @ body)
# per-person centred
cent = [np.array([max(fr, key=lambda x: x @ body) for fr in f]) for f in feet.values() if len(f) >= 5]
cc = np.concatenate([x - x.mean(0) for x in cent]); per = np.linalg.eigh(cc.T @ cc)[1][:, 0]; per *= np.sign(per @ body)
for name, n in (('body', body), ('pooled', pooled), ('per-person', per)):
    pitch = np.degrees(np.arcsin(n[2])); m, sp, k = heights(n)
    print(f'{name:10s} pitch {pitch:5.1f} height {m:.2f} spread {100*sp:.1f}% people {k}')
