"""A COLMAP model seen from above, as a PNG: the 3D points (grey, the densest 98%) and the cameras
(their centres, a short stroke along the optical axis, the first one green), projected along
"up", the cameras' mean image-up direction (a handheld or robot camera is held about level), on
the plane across it that holds the main direction of travel. matplotlib from Debian
(python3-matplotlib), without a display."""
import numpy as np

from .. import geometry


def camera_centres_and_axes(model):
    """Names, centres, optical axes and image-up directions of the cameras, in the world."""
    names, centres, axes, ups = [], [], [], []
    for im in sorted(model.images.values(), key=lambda im: im.name):
        r = geometry.rotation_of(im.qvec)  # rows: the camera's x, y (down), z axes in the world
        names.append(im.name)
        centres.append(-r.T @ np.asarray(im.tvec))
        axes.append(r[2])
        ups.append(-r[1])
    shape = lambda v: np.array(v).reshape(-1, 3)
    return names, shape(centres), shape(axes), shape(ups)


def plane_basis(centres, ups):
    """Two orthonormal directions across the mean up: the first along the main direction of
    travel (the cameras' first principal direction, made level)."""
    up = ups.mean(axis=0) if len(ups) else np.array([0.0, 0.0, 1.0])
    if np.linalg.norm(up) < 1e-9:
        up = np.array([0.0, 0.0, 1.0])
    up = up / np.linalg.norm(up)
    travel = np.array([1.0, 0.0, 0.0]) if abs(up[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    if len(centres) >= 2:
        _, _, vt = np.linalg.svd(centres - centres.mean(axis=0), full_matrices=False)
        if np.linalg.norm(vt[0] - (vt[0] @ up) * up) > 1e-6:
            travel = vt[0]
    first = travel - (travel @ up) * up
    first /= np.linalg.norm(first)
    return np.stack([first, np.cross(up, first)])


def draw(model, path, title=""):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    names, centres, axes, ups = camera_centres_and_axes(model)
    points = np.array([p.xyz for p in model.points.values()]).reshape(-1, 3)
    basis = plane_basis(centres, ups)
    fig, ax = plt.subplots(figsize=(8, 8))
    if len(points):
        p2 = points @ basis.T
        keep = np.all(np.abs(p2 - np.median(p2, axis=0)) <= np.percentile(np.abs(p2 - np.median(p2, axis=0)), 98,
                                                                          axis=0), axis=1)
        ax.scatter(p2[keep, 0], p2[keep, 1], s=0.5, c="0.55", linewidths=0, label="%d points" % len(points))
    if len(centres):
        c2 = centres @ basis.T
        a2 = axes @ basis.T
        extent = np.ptp(c2, axis=0).max() if len(c2) > 1 else 1.0
        stroke = 0.05 * (extent if extent > 0 else 1.0)
        ax.plot(c2[:, 0], c2[:, 1], "-", c="#4c72b0", lw=0.6, alpha=0.6)
        for (x, y), (dx, dy) in zip(c2, a2):
            ax.plot([x, x + stroke * dx], [y, y + stroke * dy], "-", c="#c44e52", lw=1.0)
        ax.scatter(c2[:, 0], c2[:, 1], s=12, c="#4c72b0", zorder=3, label="%d cameras" % len(c2))
        ax.scatter(c2[:1, 0], c2[:1, 1], s=40, c="#55a868", zorder=4, label="first camera")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(loc="upper right", fontsize=8)
    ax.set_title(title or "the model from above", fontsize=10)
    ax.set_xticks([])
    ax.set_yticks([])
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
