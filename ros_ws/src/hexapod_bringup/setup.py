from glob import glob

from setuptools import find_packages, setup

package_name = 'hexapod_bringup'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        # the params files, where ROS tools look for them (share/<pkg>/config)
        ('share/' + package_name + '/config', sorted(glob('config/*.yaml'))),
    ],
    zip_safe=False,
    maintainer='Hexapod testbed maintainers',
    maintainer_email='maintainers@hexapod.invalid',
    description=(
        'Bring-up: the graph launcher, the params files, the hexapod CLI, the experiments '
        'and the report.'
    ),
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'hexapod = hexapod_bringup.cli:main',
            'launch_graph = hexapod_bringup.graph_launcher:main',
        ],
    },
)
