"""Peer comparison helper, run by bench_learn.py in a SEPARATE venv that has py-dem-bones (never bundled):

    <venv>/bin/python bench/dembones_peer.py rest.npy frames.npy faces.npy bones out.npy

Runs Dem Bones (SSDR, linear blend skinning) on the frames and saves its reconstruction (F, V, 3) and
timing to out.npy / out.json.  Only numpy and py_dem_bones are imported."""
import json
import sys
import time

import numpy as np
import py_dem_bones


def main(argv):
    rest, frames, faces = (np.load(p) for p in argv[:3])
    bones, out = int(argv[3]), argv[4]
    t0 = time.perf_counter()
    res = py_dem_bones.solve_skinning(rest, frames, bones, faces=[list(f) for f in faces], max_influences=4,
                                      iterations=30)
    seconds = time.perf_counter() - t0
    W = np.asarray(res.weights, dtype=np.float64)
    T = np.asarray(res.transforms, dtype=np.float64)
    F, V = frames.shape[:2]
    if W.shape[0] != V:                       # (B, V) -> (V, B)
        W = W.T
    B = W.shape[1]
    T = T.reshape(F, B, 4, 4) if T.size == F * B * 16 else T.reshape(B, F, 4, 4).transpose(1, 0, 2, 3)
    homog = np.concatenate([rest, np.ones((V, 1))], axis=1)
    posed_b = np.einsum("fbij,vj->fvbi", T, homog)[..., :3]
    recon = np.einsum("vb,fvbi->fvi", W, posed_b)
    err_direct = np.abs(recon - frames).mean()
    # transforms may be stored transposed (row-vector convention): keep the better reading
    posed_bt = np.einsum("fbji,vj->fvbi", T, homog)[..., :3]
    recon_t = np.einsum("vb,fvbi->fvi", W, posed_bt)
    if np.abs(recon_t - frames).mean() < err_direct:
        recon = recon_t
    np.save(out, recon)
    with open(out + ".json", "w") as f:
        json.dump({"seconds": seconds, "bones_found": int(B)}, f)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
