from glob import glob

from setuptools import find_packages, setup

package_name = 'hexapod_sim'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    # The default params file ships inside the package (importlib.resources) ...
    package_data={package_name: ['config/*.yaml']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        # ... and in share/<pkg>/config (ament_index_python lookups).
        ('share/' + package_name + '/config', sorted(glob(package_name + '/config/*.yaml'))),
    ],
    zip_safe=False,
    maintainer='Hexapod testbed maintainers',
    maintainer_email='maintainers@hexapod.invalid',
    description=(
        'Planar hexapod model, kinematics, dynamics and parameters, with the simulator node.'
    ),
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'hexapod_sim = hexapod_sim.sim_node:main',
        ],
    },
)
