from setuptools import find_packages, setup

package_name = 'my_controller'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    zip_safe=False,
    maintainer='You',
    maintainer_email='you@example.invalid',
    description='An example joint controller that joins a running hexapod graph.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'my_controller = my_controller.node:main',
        ],
    },
)
