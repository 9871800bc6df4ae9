"""Writing small COPC files for the tests (copclib; laspy reads COPC but does not write it)."""

import numpy as np


def write_copc(path, xyz, intensity, scale=(0.001, 0.001, 0.001)):
    """A COPC file of `xyz`: a root node and the eight voxels of the first level.

    The root holds every 8th point, the rest go to the voxels, so that a bounds query
    reads only some nodes. Scale 1 mm; point format 6.
    """
    import copclib as c

    lo = xyz.min(axis=0)
    half = float((xyz.max(axis=0) - lo).max()) / 2 + 1.0
    centre = lo + half - 0.5
    cfg = c.CopcConfigWriter(6, c.Vector3(*scale),
                             c.Vector3(*np.floor(lo).tolist()))
    cfg.copc_info.center_x, cfg.copc_info.center_y, cfg.copc_info.center_z = centre.tolist()
    cfg.las_header.min = c.Vector3(*xyz.min(axis=0).tolist())
    cfg.las_header.max = c.Vector3(*xyz.max(axis=0).tolist())
    cfg.copc_info.halfsize = half
    cfg.copc_info.spacing = 2 * half / 128
    w = c.FileWriter(str(path), cfg)

    def points(rows):
        p = c.Points(w.copc_config.las_header)
        for i in rows:
            q = p.CreatePoint()
            q.x, q.y, q.z = (float(v) for v in xyz[i])
            q.intensity = int(intensity[i])
            q.return_number, q.number_of_returns = 1, 1
            p.AddPoint(q)
        return p

    n = len(xyz)
    root = np.arange(n) % 8 == 0
    w.AddNode(c.VoxelKey(0, 0, 0, 0), points(np.flatnonzero(root)))
    depth = 1
    cells = 2 ** depth
    idx = np.clip(((xyz - (centre - half)) / (2 * half) * cells).astype(int), 0, cells - 1)
    rest = np.flatnonzero(~root)
    keys = {}
    for i in rest:
        keys.setdefault(tuple(idx[i]), []).append(i)
    for key, rows in keys.items():
        w.AddNode(c.VoxelKey(depth, *map(int, key)), points(rows))
    w.Close()
    return path
