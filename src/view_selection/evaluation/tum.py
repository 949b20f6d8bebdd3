"""TUM RGB-D layout: the lists (rgb.txt, depth.txt, groundtruth.txt) and the flat camera.yaml
that the C++ side reads too (io/tum_dataset)."""
import re


class TumError(Exception):
    """A TUM-layout file that cannot be read."""


def read_list(path):
    """Lines of a TUM list without comments, split; the first column must be a stamp."""
    rows = []
    with open(path) as f:
        for number, line in enumerate(f, 1):
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            parts = line.split()
            try:
                float(parts[0])
            except ValueError:
                raise TumError("%s:%d: the first column is not a stamp" % (path, number))
            rows.append(parts)
    return rows


def read_trajectory(path):
    """[(stamp, (tx, ty, tz), (qw, qx, qy, qz))] of a TUM trajectory (groundtruth.txt: stamp tx ty
    tz qx qy qz qw), in file order."""
    poses = []
    for parts in read_list(path):
        if len(parts) < 8:
            raise TumError("%s: a pose line needs 8 columns: %s" % (path, " ".join(parts)))
        v = [float(p) for p in parts[:8]]
        poses.append((v[0], tuple(v[1:4]), (v[7], v[4], v[5], v[6])))
    return poses


def write_trajectory(path, poses):
    """The inverse of read_trajectory."""
    with open(path, "w") as f:
        f.write("# timestamp tx ty tz qx qy qz qw\n")
        for stamp, (x, y, z), (qw, qx, qy, qz) in poses:
            f.write("%.6f %.9g %.9g %.9g %.9g %.9g %.9g %.9g\n" % (stamp, x, y, z, qx, qy, qz, qw))


def read_camera_yaml(path):
    """{fx, fy, cx, cy[, width, height]} of a flat camera.yaml."""
    values = {}
    with open(path) as f:
        for line in f:
            m = re.match(r"^\s*(fx|fy|cx|cy|width|height)\s*:\s*([-+0-9.eE]+)\s*$", line)
            if m:
                values[m.group(1)] = float(m.group(2))
    missing = [k for k in ("fx", "fy", "cx", "cy") if k not in values]
    if missing:
        raise TumError("%s: missing %s (a flat camera.yaml with fx, fy, cx, cy is needed)" % (path, ", ".join(missing)))
    return values
