"""SIFT features with OpenCV (Debian's OpenCV 4.6 has SIFT in its main module), stored the way
COLMAP 3.8 stores its own, so that every COLMAP command reads them:

  keypoints    float32 N x 4: x, y (COLMAP's pixel convention: the top-left pixel's centre is
               (0.5, 0.5), so OpenCV's coordinates + 0.5), scale (OpenCV's size / 2), orientation
               [rad]
  descriptors  uint8 N x 128: RootSIFT (L1-normalised, square-rooted: COLMAP's default
               SiftExtraction.normalization L1_ROOT), times 512, rounded and clipped at 255, as
               COLMAP's FeatureDescriptorsToUnsignedByte

The bridge extracts here instead of in COLMAP's feature_extractor: the same image costs about a
fifth of the CPU (docs/live.md), no process is started per batch, and the node, which decoded the
image first, is left alone (it must receive every frame).
"""
import math

import cv2
import numpy as np

PIXEL_CENTRE = 0.5  # COLMAP's keypoint coordinates minus OpenCV's


class Features:
    """xy (N x 2, OpenCV pixel convention), scale, orientation [rad], descriptors (N x 128
    float32, unit L2 norm: RootSIFT), strongest first."""
    __slots__ = ("xy", "scale", "orientation", "descriptors")

    def __init__(self, xy, scale, orientation, descriptors):
        self.xy = np.asarray(xy, np.float64).reshape(-1, 2)
        self.scale = np.asarray(scale, np.float32).reshape(-1)
        self.orientation = np.asarray(orientation, np.float32).reshape(-1)
        self.descriptors = np.asarray(descriptors, np.float32).reshape(-1, 128)

    def __len__(self):
        return len(self.xy)

    def to_colmap(self):
        """(keypoints N x 4 float32, descriptors N x 128 uint8) for the database."""
        kp = np.zeros((len(self), 4), np.float32)
        kp[:, :2] = self.xy + PIXEL_CENTRE
        kp[:, 2] = self.scale
        kp[:, 3] = self.orientation
        desc = np.clip(np.round(self.descriptors * 512.0), 0, 255).astype(np.uint8)
        return kp, desc

    @staticmethod
    def from_colmap(keypoints, descriptors):
        """Features back from the database (ours or COLMAP's own extractor's)."""
        kp = np.asarray(keypoints, np.float32)
        desc = np.asarray(descriptors, np.float32)
        norms = np.linalg.norm(desc, axis=1, keepdims=True)
        desc = desc / np.maximum(norms, 1e-12)
        if kp.shape[1] >= 6:  # affine shape: scale and orientation of its first column
            scale = np.hypot(kp[:, 2], kp[:, 4])
            orientation = np.arctan2(kp[:, 4], kp[:, 2])
        elif kp.shape[1] == 4:
            scale, orientation = kp[:, 2], kp[:, 3]
        else:
            scale, orientation = np.ones(len(kp)), np.zeros(len(kp))
        return Features(kp[:, :2].astype(np.float64) - PIXEL_CENTRE, scale, orientation, desc)


def root_sift(descriptors):
    """OpenCV's SIFT descriptors (L2-normalised, x512) as RootSIFT with unit L2 norm."""
    d = np.asarray(descriptors, np.float32)
    d = d / np.maximum(d.sum(axis=1, keepdims=True), 1e-12)
    return np.sqrt(d)


class SiftExtractor:
    """max_features: the strongest N by response (0: all); contrast_threshold: OpenCV's (0.04 is
    its default; 0.02 gives about COLMAP's number of features on VGA images, docs/live.md)."""

    def __init__(self, max_features=2048, contrast_threshold=0.02, edge_threshold=10.0):
        self.max_features = int(max_features)
        self.sift = cv2.SIFT_create(nfeatures=max(0, self.max_features), contrastThreshold=float(contrast_threshold),
                                    edgeThreshold=float(edge_threshold))

    def extract(self, gray):
        """Features of an 8-bit grey image (H x W uint8)."""
        if gray is None or gray.ndim != 2 or gray.dtype != np.uint8 or gray.size == 0:
            raise ValueError("not an 8-bit grey image")
        keypoints, descriptors = self.sift.detectAndCompute(gray, None)
        if not keypoints:
            return Features(np.zeros((0, 2)), [], [], np.zeros((0, 128)))
        # strongest first (the matcher's first pass uses the first few hundred); OpenCV may keep
        # ties beyond N
        order = np.argsort([-k.response for k in keypoints], kind="stable")
        if self.max_features:
            order = order[:self.max_features]
        keypoints = [keypoints[i] for i in order]
        descriptors = descriptors[order]
        xy = np.array([k.pt for k in keypoints], np.float64)
        scale = np.array([k.size / 2.0 for k in keypoints], np.float32)
        orientation = np.array([math.radians(k.angle) for k in keypoints], np.float32)
        return Features(xy, scale, orientation, root_sift(descriptors))

    def extract_file(self, path):
        """Features of an image file; ValueError when it cannot be read."""
        gray = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
        if gray is None:
            raise ValueError("cannot read %s as an image" % path)
        return self.extract(gray)
