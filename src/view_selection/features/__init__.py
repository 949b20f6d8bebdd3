"""Local features of the keyframe images, in COLMAP's database format (sift.py)."""
