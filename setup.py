# Copyright 2026 The cone_feeder_sim Authors
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""Setup script of the ament_python package cone_feeder_sim."""

from glob import glob
import os
from pathlib import Path
import shutil
import subprocess
import sys

from setuptools import find_packages, setup
from setuptools.command.install import install

package_name = 'cone_feeder_sim'
#: Set to skip the compile after an install (the first start then compiles, about a minute).
NO_COMPILE = 'CONE_FEEDER_SIM_NO_COMPILE'


class InstallWithKernels(install):
    """
    Install, then leave numba's cache of the kernels warm in the installed package.

    A colcon build (ament_python: ``setup.py install --single-version-externally-managed``)
    ends here, so that the first ``ros2 run cone_feeder_sim sim_node`` compiles nothing.
    Kernels cached in the source tree for this Python (by scripts/setup_venv.sh) are copied
    first: numba keys its cache on the source file's time stamp and size, which the install
    keeps, so only what they lack is compiled. A failure (numba missing at build time, a
    compile that hangs for 30 minutes) is a warning: the first start then compiles, as
    without this step. A staged install (``--root``: a wheel for pip, a Debian package) is
    left alone: numba's cache would not match the files where they land.
    """

    def run(self) -> None:
        """Run the install, then ``cone-feeder-sim compile`` against the installed package."""
        super().run()
        if os.environ.get(NO_COMPILE) or self.root:
            return
        source = Path(__file__).resolve().parent / package_name
        target = Path(self.install_lib) / package_name
        version = f'py{sys.version_info.major}{sys.version_info.minor}'  # this Python's only
        try:
            for cached in source.glob(f'**/__pycache__/*.{version}*.nb[ic]'):
                copy = target / cached.relative_to(source)
                copy.parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(cached, copy)
            env = dict(os.environ)
            env['PYTHONPATH'] = os.pathsep.join(
                [self.install_lib] + ([env['PYTHONPATH']] if env.get('PYTHONPATH') else []))
            done = subprocess.run([sys.executable, '-m', f'{package_name}.cli', 'compile'],
                                  cwd=self.install_lib, env=env, stderr=subprocess.STDOUT,
                                  check=False, timeout=1800)
            failed = done.returncode != 0
        except (OSError, subprocess.TimeoutExpired) as exc:
            self.warn(f'{exc}')
            failed = True
        if failed:
            self.warn('compiling the kernels failed; the first start will compile them '
                      f'(set {NO_COMPILE}=1 to skip this step)')


setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml') + glob('config/*.json')
         + glob('config/*.csv')),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
    ],
    # The ROS 2 Python packages (rclpy, message packages) come from the ROS installation
    # (apt) or from the PyPI ros-jazzy-* wheels; they are deliberately not listed here.
    # Floors: requirements/runtime.txt says why each is the oldest version the code runs on.
    install_requires=['setuptools', 'numpy>=1.23.2', 'numba>=0.57', 'pyyaml>=6.0',
                      'mcap>=1.6.0', 'rosbags>=0.10.8', 'matplotlib>=3.6', 'scipy>=1.9.2'],
    # `cone-feeder-sim sweep` runs on Dask (dask.distributed); only the sweep needs it.
    # `run --view` and the RL environment's render_mode 'human' serve a live Foxglove view.
    extras_require={'sweep': ['dask[distributed]>=2024.1'],
                    'rl': ['gymnasium>=1.0', 'stable-baselines3>=2.4'],
                    'view': ['foxglove-sdk>=0.30']},
    python_requires='>=3.11',
    zip_safe=True,
    maintainer='cone_feeder_sim maintainers',
    maintainer_email='maintainers@cone-feeder-sim.invalid',
    description='Simulation of product pieces on the rotating cone feeder of a multihead '
                'weigher, with a ROS 2 node and MCAP logging.',
    license='Apache-2.0',
    tests_require=['pytest'],
    cmdclass={'install': InstallWithKernels},
    entry_points={
        'console_scripts': [
            'cone-feeder-sim = cone_feeder_sim.cli:main',
            'sim_node = cone_feeder_sim.ros.sim_node:main',
            'replay_node = cone_feeder_sim.ros.replay_node:main',
            'example_controller = cone_feeder_sim.ros.example_controller:main',
            'policy_controller = cone_feeder_sim.ros.policy_controller:main',
            'twin_node = cone_feeder_sim.ros.twin_node:main',
            'camera_node = cone_feeder_sim.ros.camera_node:main',
        ],
    },
)
