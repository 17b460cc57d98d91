"""ament_python / setuptools build for cdh_planner.

Works both under colcon (ROS 2 Jazzy install) and as a plain `pip install -e .`.
Exact dependency pins live in requirements.txt; install_requires only names them.

install_requires names the runtime dependencies that are Python distributions. The ROS ones
(rclpy, builtin_interfaces, rcl_interfaces, ament_index_python, the message packages,
cdh_planner_interfaces, control_msgs) are declared in package.xml: under colcon they come
from the ROS install and the workspace; for the venv, requirements.txt pins their PyPI wheels
and `make venv` builds the interfaces of interfaces/ (test/test_packaging.py checks that
every import of the package is declared here or there).
"""
from glob import glob

from setuptools import find_packages, setup

package_name = 'cdh_planner'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    # the directions' draws (atlas/domain.py: read instead of importing numpy.random)
    package_data={'cdh_planner.atlas': ['directions.npy'],
                  # verify's compiled JSON, built where it is installed (compiled_json.py)
                  'cdh_planner': ['compiled_json.c', 'ryu/*']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml', 'LICENSE']),
        # glob so robot / problem files added later are picked up without editing here
        ('share/' + package_name + '/config', sorted(glob('config/*.yaml') + glob('config/*.rviz')
                                                      + glob('config/*.json'))),
        ('share/' + package_name + '/config/problems', sorted(glob('config/problems/*.yaml'))),
        ('share/' + package_name + '/config/scenes', sorted(glob('config/scenes/*.yaml'))),
        ('share/' + package_name + '/config/sweeps', sorted(glob('config/sweeps/*.yaml'))),
        ('share/' + package_name + '/launch', sorted(glob('launch/*.launch.py'))),
    ],
    install_requires=['setuptools', 'numpy', 'scipy', 'pyyaml', 'matplotlib', 'tqdm', 'threadpoolctl', 'numba', 'orjson', 'toppra',
                      'coal', 'trimesh', 'mujoco',
                      'mcap', 'mcap-ros2-support', 'rosbags', 'ray'],
    zip_safe=True,
    maintainer='cdh_planner maintainers',
    maintainer_email='maintainer@example.com',
    description='Wrench-feasible path planning for cable-driven hexapods.',
    license='Apache-2.0',
    python_requires='>=3.10',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'cdh-planner = cdh_planner.cli:main',
        ],
    },
)
