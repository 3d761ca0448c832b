from setuptools import find_packages, setup

package_name = 'vp_scene'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', ['config/fastdds.xml']),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='vp-suite maintainers',
    maintainer_email='maintainers@vp-suite.invalid',
    description='The simulated world: corn-field scenes (Corn50 PLY or procedural plants, layouts, wind noise), the capture model, rendering and the simulated drones, with the scene and sim_drone nodes; and what every package shares (camera geometry, plan files, ROS message conversions, node runtime).',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'scene = vp_scene.node_entry:scene',
            'sim_drone = vp_scene.node_entry:sim_drone',
        ],
    },
)
