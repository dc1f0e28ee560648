from setuptools import find_packages, setup

package_name = 'hexapod_sim'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    zip_safe=False,
    maintainer='Hexapod testbed maintainers',
    maintainer_email='maintainers@hexapod.invalid',
    description=(
        'The planar hexapod model (dynamics, body, contact, actuators, the engine) and the '
        'simulator node.'
    ),
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'hexapod_sim = hexapod_sim.sim_node:main',
        ],
    },
)
