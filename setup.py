"""For catkin only (CMakeLists.txt's catkin_python_setup): the library lanelib, so that a
workspace's devel or install space can import it wherever the programs run from. The project
itself needs no installing: setup.sh makes .venv and the programs run from the repository."""

from catkin_pkg.python_setup import generate_distutils_setup
from setuptools import setup

setup(**generate_distutils_setup(packages=['lanelib', 'lanelib.sim'], package_dir={'': '.'}))
