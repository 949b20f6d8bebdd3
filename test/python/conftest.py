# The unit tier of the Python module: no ROS master, no COLMAP. Run by scripts/test through
# catkin (run_tests_view_selection_pytest_python_unit), or alone: python3 -m pytest test/python
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "src"))
