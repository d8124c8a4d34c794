"""A held-out "animal pose sequence" made from Keenan Crane's Spot (public domain; issue #34):
legs swing, the head nods and the body bends; per frame an OBJ with Spot's triangles (the
per-frame ground truth). Usage: spot_walk.py SPOT.obj OUT_DIR FRAMES"""
import sys, numpy as np
src, out, n = sys.argv[1], sys.argv[2], int(sys.argv[3])
V, F = [], []
for l in open(src):
    if l.startswith('v '): V.append([float(x) for x in l.split()[1:4]])
    elif l.startswith('f '): F.append([int(x.split('/')[0]) for x in l.split()[1:4]])
V = np.array(V); F = np.array(F)
# Spot: y up, z forward (head at +z), x sideways. Legs are below y ~ -0.25.
import os; os.makedirs(out, exist_ok=True)
def rot_x(p, pivot, ang):
    c, s = np.cos(ang), np.sin(ang); q = p - pivot
    return pivot + np.stack([q[:,0], c*q[:,1]-s*q[:,2], s*q[:,1]+c*q[:,2]], 1)
for f in range(n):
    t = 2*np.pi*f/n
    P = V.copy()
    leg = P[:,1] < -0.25
    w = np.clip((-0.25 - P[:,1]) / 0.1, 0, 1)[:,None]   # smooth blend into the hip
    for front in (True, False):
        for left in (True, False):
            sel = leg & ((P[:,2] > 0.1) == front) & ((P[:,0] > 0) == left)
            phase = (0 if front == left else np.pi)
            ang = 0.5*np.sin(t+phase)
            hip = np.array([0, -0.25, P[sel,2].mean() if sel.any() else 0])
            moved = rot_x(P[sel], hip, ang)
            P[sel] = (1-w[sel])*P[sel] + w[sel]*moved
    head = np.clip((P[:,2]-0.45)/0.15, 0, 1)[:,None]
    P = (1-head)*P + head*rot_x(P, np.array([0,0.3,0.45]), 0.35*np.sin(2*t))
    # body bend sideways
    P[:,0] += 0.08*np.sin(t)*(P[:,2]**2)
    with open(f'{out}/frame_{f:03d}.obj','w') as fh:
        for p in P: fh.write(f'v {p[0]:.6f} {p[1]:.6f} {p[2]:.6f}\n')
        for tri in F: fh.write(f'f {tri[0]} {tri[1]} {tri[2]}\n')
