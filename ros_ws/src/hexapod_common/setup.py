from setuptools import find_packages, setup

package_name = 'hexapod_common'

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
        'What every node shares: parameters, gait and kinematics, message codec and '
        'authentication, the topic table, the Fast DDS profile and the node runtime.'
    ),
    license='Apache-2.0',
)
