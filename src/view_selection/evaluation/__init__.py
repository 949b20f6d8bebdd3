"""The evaluation maths of the tools and benchmarks: trajectory alignment and ATE
(trajectory.py), TUM-layout lists and camera.yaml (tum.py)."""
