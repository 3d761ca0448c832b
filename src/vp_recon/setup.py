from setuptools import find_packages, setup

package_name = 'vp_recon'

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
    description='Reconstruct the images of a flight (rendered by the simulated drones of vp_scene, or real) with COLMAP (CPU) and score with the Chamfer distance; the recon, recorder and viewer nodes.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'recon = vp_recon.node_entry:recon',
            'reconstruct = vp_recon.cli:main',
            'recorder = vp_recon.node_entry:recorder',
            'viewer = vp_recon.node_entry:viewer',
        ],
        # the planner's simulated flights (vp_scene.flights.load_simulator): found, not imported
        'vp_scene.flight_simulators': ['reconstruction = vp_recon.sim_flights:SceneFlights'],
    },
)
