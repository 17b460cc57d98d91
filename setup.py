"""ament_python / setuptools build for cdh_planner.

Works both under colcon (ROS 2 Jazzy install) and as a plain `pip install -e .`.
Exact dependency pins live in requirements.txt; install_requires only names them.
"""
from glob import glob

from setuptools import find_packages, setup

package_name = 'cdh_planner'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        # glob so robot / problem files added later are picked up without editing here
        ('share/' + package_name + '/config', sorted(glob('config/*.yaml'))),
        ('share/' + package_name + '/config/problems', sorted(glob('config/problems/*.yaml'))),
    ],
    install_requires=['setuptools', 'numpy', 'scipy', 'pyyaml', 'matplotlib', 'tqdm', 'threadpoolctl', 'numba', 'toppra'],
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
