from setuptools import find_packages, setup

package_name = 'hexapod_metrics'

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
        'Performance indices, the recorder, bags and the offline analysis.'
    ),
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'metrics = hexapod_metrics.metrics_node:main',
            'markers = hexapod_metrics.marker_node:main',
            'foxglove_bridge = hexapod_metrics.foxglove_node:main',
        ],
    },
)
