from setuptools import find_packages, setup

package_name = 'vp_planner'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='vp-suite maintainers',
    maintainer_email='maintainers@vp-suite.invalid',
    description='EGP-VP view planning: the paper reward, ensemble-GP Bayesian optimization, baselines, the planner node, and the dispatcher that sends each drone of a fleet its pose.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'planner = vp_planner.node_entry:planner',
            'dispatcher = vp_planner.node_entry:dispatcher',
            'plan = vp_planner.cli:main',
        ],
    },
)
