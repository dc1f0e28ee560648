from setuptools import find_packages, setup

package_name = 'hexapod_control'

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
        'The controllers (PD-P, PD-P&F) and the trajectory generator node, and the in-process '
        'closed loop.'
    ),
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'trajectory_generator = hexapod_control.trajectory_node:main',
            'pd_p_controller = hexapod_control.controller_node:main_pd_p',
            'pd_pf_controller = hexapod_control.controller_node:main_pd_pf',
        ],
        'hexapod.controllers': [
            'pd_p = hexapod_control.core.builtin:PdP',
            'pd_pf = hexapod_control.core.builtin:PdPf',
            'pd_alpha = hexapod_control.core.pd_alpha:PdAlpha',
        ],
    },
)
