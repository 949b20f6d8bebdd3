# The Python module (src/view_selection), for catkin_python_setup(); not for pip.
from setuptools import setup
from catkin_pkg.python_setup import generate_distutils_setup

setup(**generate_distutils_setup(
    packages=["view_selection", "view_selection.colmap", "view_selection.evaluation", "view_selection.features",
              "view_selection.live", "view_selection.matching", "view_selection.refinement", "view_selection.tools"],
    package_dir={"": "src"}))
